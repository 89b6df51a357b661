// geo.train / geo.resume (geo_train's trainer, blocking, with a per-step callback) and geo.state_dicts
// (a checkpoint's weights as PyTorch state dicts).
#include "bindings.h"

#include "core/config.h"
#include "core/logging.h"
#include "models/conv.h"
#include "geo/geo.h"
#include "pipeline/checkpoint.h"
#include "pipeline/run_folder.h"
#include "train/trainer.h"

#include <exception>
#include <memory>

namespace geo::python {

using namespace pybind11::literals;

namespace {

// Hands each training step to a Python callable (with the GIL) as a dict. What the callable raises
// stops the run at once (as an exception of any sink does) and is raised again by geo.train.
class CallbackSink : public MetricsSink {
 public:
  explicit CallbackSink(py::object callback) : callback_(std::move(callback)) {}
  ~CallbackSink() override {
    py::gil_scoped_acquire acquire;
    callback_ = py::object();
  }
  void on_step(const StepRecord& r) override {
    py::gil_scoped_acquire acquire;
    py::dict losses;
    for (const auto& [name, value] : r.losses) losses[py::str(name)] = value;
    py::dict step("stage"_a = r.stage, "stage_index"_a = r.stage_index, "iteration"_a = r.iteration,
                  "stage_iterations"_a = r.stage_iterations, "global_step"_a = r.global_step, "losses"_a = losses,
                  "lr"_a = r.lr, "grad_norm"_a = r.grad_norm, "skipped_steps"_a = r.skipped_steps);
    if (!r.camera.empty()) step["camera"] = r.camera;
    try {
      callback_(step);
    } catch (py::error_already_set&) {
      raised = std::current_exception();
      throw std::runtime_error("the training callback raised an exception");
    }
  }
  std::exception_ptr raised;

 private:
  py::object callback_;
};

// Runs `body` (geo::train or geo::resume) without the GIL; 130 (a signal) becomes KeyboardInterrupt
// once the checkpoint is written, as geo_train exits 130.
template <class Body>
std::string run_training(const std::shared_ptr<CallbackSink>& sink, const std::string& folder_hint, Body&& body) {
  int rc = 0;
  std::string run_dir = folder_hint;
  try {
    py::gil_scoped_release release;
    rc = body(run_dir);
  } catch (...) {
    if (sink && sink->raised) std::rethrow_exception(sink->raised);
    throw;
  }
  if (rc == 130) {
    PyErr_SetString(PyExc_KeyboardInterrupt, ("training interrupted: checkpoint written in " + run_dir +
                                              "; geo.resume('" + run_dir + "') continues")
                                                 .c_str());
    throw py::error_already_set();
  }
  if (rc != 0) throw Error("training ended with code " + std::to_string(rc));
  return run_dir;
}

TrainOptions train_options(const std::string& run_dir, const std::string& init, const std::string& device,
                           const std::shared_ptr<CallbackSink>& sink) {
  TrainOptions o;
  o.run_dir = run_dir, o.init = init, o.device = device;
  if (sink) o.sinks.push_back(sink);
  return o;
}

}  // namespace

void bind_train(py::module_& m) {
  m.def(
      "train",
      [](py::object config, const std::string& run_dir, const std::vector<std::string>& overrides,
         const std::string& init, const std::string& device, py::object callback) {
        Config cfg;
        if (py::isinstance<py::dict>(config)) {
          const std::string yaml = py::str(py::module_::import("yaml").attr("safe_dump")(config));
          cfg = parse_config(yaml, "<config dict>", overrides);
        } else {
          cfg = load_config(resolve_config_path(py::cast<std::string>(py::str(config))), overrides);
        }
        setup_logging(cfg.logging.level);
        const auto sink = callback.is_none() ? nullptr : std::make_shared<CallbackSink>(callback);
        const auto options = train_options(run_dir, init, device, sink);
        return run_training(sink, run_dir, [&](std::string& dir) { return train(cfg, options, &dir); });
      },
      "config"_a, py::kw_only(), "run_dir"_a = "", "overrides"_a = std::vector<std::string>{}, "init"_a = "",
      "device"_a = "", "callback"_a = py::none(),
      "geo_train: trains as the config says (a YAML path, a shipped config's name such as 'stage1.yaml', or a dict\n"
      "of the same keys), with overrides ['key=value', ...] as --set. Blocks until done and returns the run folder.\n"
      "callback(step) is called after every step with {stage, iteration, global_step, losses, lr, grad_norm, ...};\n"
      "what it raises stops the run. Ctrl-C (SIGINT) writes a checkpoint and raises KeyboardInterrupt;\n"
      "geo.resume(run_dir) continues.");
  m.def(
      "resume",
      [](const std::string& run_dir, const std::string& device, py::object callback) {
        const auto sink = callback.is_none() ? nullptr : std::make_shared<CallbackSink>(callback);
        const auto options = train_options("", "", device, sink);
        return run_training(sink, run_dir, [&](std::string&) { return resume(run_dir, options); });
      },
      "run_dir"_a, py::kw_only(), "device"_a = "", "callback"_a = py::none(),
      "geo_train --resume: continues the run in run_dir from its latest checkpoint.");
  // The networks themselves (eval mode, BatchNorm unfolded, as training checkpoints hold them): what
  // geo.nn's plain PyTorch modules are checked against, and raw outputs for those who want them.
  py::class_<Networks>(m, "Networks",
                       "A checkpoint's networks as trained (eval mode, BatchNorm not folded): raw network outputs.")
      .def_static(
          "load",
          [](const std::string& path) {
            py::gil_scoped_release release;
            CheckpointFile file(resolve_checkpoint(path));
            Networks nets = file.networks();
            nets.depth->eval();
            nets.pose->eval();
            if (nets.flow) nets.flow->eval();
            return nets;
          },
          "checkpoint"_a)
      .def(
          "depth_net",
          [](Networks& n, py::handle image) {
            const auto x = tensor_arg(image, "image");
            py::gil_scoped_release release;
            torch::NoGradGuard no_grad;
            return n.depth->forward(x).disp;
          },
          "image"_a, "DepthNet: image [B,3,H,W] RGB in [0,1] -> disparities at 4 scales, finest first.")
      .def(
          "pose_net",
          [](Networks& n, py::handle target, const py::sequence& sources) {
            const auto t = tensor_arg(target, "target");
            std::vector<torch::Tensor> srcs;
            for (size_t i = 0; i < sources.size(); ++i)
              srcs.push_back(tensor_arg(sources[i], "sources[" + std::to_string(i) + "]"));
            py::gil_scoped_release release;
            torch::NoGradGuard no_grad;
            return n.pose->forward(t, srcs);
          },
          "target"_a, "sources"_a,
          "PoseNet: target and sources [B,3,H,W] in [0,1] -> [B,N,6] (tx, ty, tz, rx, ry, rz).")
      .def(
          "flow_net",
          [](Networks& n, py::handle input) {
            if (!n.flow) throw Error("this checkpoint has no FlowNet");
            const auto x = tensor_arg(input, "input");
            py::gil_scoped_release release;
            torch::NoGradGuard no_grad;
            return n.flow->forward(x).flow;
          },
          "input"_a, "FlowNet: its 12-channel input [B,12,H,W] -> residual flows in pixels at 4 scales, finest first.")
      .def_property_readonly("has_flow", [](const Networks& n) { return static_cast<bool>(n.flow); });
  m.def(
      "onednn_channel_padding", [](py::handle x) { return onednn_channel_padding(tensor_arg(x, "x")); }, "x"_a,
      "How many zero channels geo's convolutions append to the input x of a convolution: the oneDNN of\n"
      "LibTorch 2.x computes some channel counts wrongly on the CPU (models/conv.h); geo.nn applies the same rule.");
  m.def(
      "state_dicts",
      [](const std::string& path) {
        Networks nets;
        std::string spec;
        {
          py::gil_scoped_release release;
          CheckpointFile file(resolve_checkpoint(path));
          nets = file.networks();
          spec = nets.spec.to_yaml();
        }
        const auto ordered = py::module_::import("collections").attr("OrderedDict");
        auto state = [&](const torch::nn::Module& net) {
          py::object d = ordered();
          for (const auto& p : net.named_parameters()) d[py::str(p.key())] = p.value().detach();
          for (const auto& b : net.named_buffers()) d[py::str(b.key())] = b.value().detach();
          return d;
        };
        py::dict out;
        out["depth"] = state(*nets.depth);
        out["pose"] = state(*nets.pose);
        out["flow"] = nets.flow ? state(*nets.flow) : py::none();
        try {
          out["spec"] = py::module_::import("yaml").attr("safe_load")(spec);
        } catch (py::error_already_set&) {
          out["spec"] = spec;  // no PyYAML: the architecture as YAML text
        }
        return out;
      },
      "checkpoint"_a,
      "The weights of a checkpoint, run folder or model file as PyTorch state dicts (unfolded BatchNorm):\n"
      "{depth, pose, flow (None without a FlowNet): OrderedDict name -> tensor, spec: the architecture}.");
}

}  // namespace geo::python
