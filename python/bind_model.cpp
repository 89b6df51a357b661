// geo.Model: include/geo/geo.h from Python. Arguments are converted with the GIL held; the networks
// run with it released, so Python threads calling one Model run at once.
#include "bindings.h"

#include "geo/geo.h"

#include <optional>
#include <utility>

namespace geo::python {

using namespace pybind11::literals;

namespace {

// flow() and flow_parts()'s arguments as geo takes them (converted with the GIL held).
struct PairArgs {
  torch::Tensor from, to, intrinsics, previous;
};
PairArgs pair_args(py::handle from, py::handle to, py::handle intrinsics, py::handle previous) {
  return {image_arg(from, "from"), image_arg(to, "to"), optional_tensor_arg(intrinsics, "intrinsics"),
          previous.is_none() ? torch::Tensor() : image_arg(previous, "previous")};
}

py::object with_scale(torch::Tensor result, std::vector<double> scale, bool wanted) {
  if (!wanted) return py::cast(std::move(result));
  return py::make_tuple(std::move(result), std::move(scale));
}

// A sequence of images (frames[i] named in errors).
std::vector<torch::Tensor> images_arg(const py::sequence& frames, const std::string& what) {
  std::vector<torch::Tensor> xs;
  for (size_t i = 0; i < frames.size(); ++i) xs.push_back(image_arg(frames[i], what + "[" + std::to_string(i) + "]"));
  return xs;
}

// A sequence's frames: a geo.FrameSource (geo.io.Frames: a folder or a video, read as needed) as it
// is, else a sequence of images held in `held`.
FrameSource& frames_arg(py::handle frames, std::optional<TensorFrames>& held) {
  if (py::isinstance<FrameSource>(frames)) return frames.cast<FrameSource&>();
  if (py::isinstance<py::str>(frames))
    throw Error("frames: a path names no frames here: geo.io.Frames(path, size=...) reads a folder or a video");
  held.emplace(images_arg(frames.cast<py::sequence>(), "frames"));
  return *held;
}

// Model.load's and Model.create's keyword arguments.
LoadOptions load_options(const std::string& device, const std::string& precision, int threads,
                         const py::object& calibration, bool keep_float_weights) {
  LoadOptions options;
  options.device = device, options.precision = precision, options.threads = threads;
  options.keep_float_weights = keep_float_weights;
  if (!calibration.is_none()) options.calibration = images_arg(calibration.cast<py::sequence>(), "calibration");
  return options;
}

}  // namespace

void bind_model(py::module_& m) {
  m.def("image", &image_arg, "image"_a, "what"_a = "image",
        "The tensor geo sees for an image: torch tensors as they are ([3,H,W], [B,3,H,W]); numpy arrays\n"
        "([H,W,3], [B,H,W,3], uint8 0..255 or float 0..1) as a channels-first view of the same memory.");
  m.def("kitti_like_intrinsics", &kitti_like_intrinsics, "height"_a, "width"_a,
        "KITTI's proportions at height x width (fx = 0.58 W, fy = 1.92 H, principal point at the centre): [3,3] "
        "float64.");

  m.def(
      "chain_poses",
      [](const py::sequence& motions, std::vector<double> scales) {
        std::vector<torch::Tensor> ms;
        for (size_t i = 0; i < motions.size(); ++i)
          ms.push_back(tensor_arg(motions[i], "motions[" + std::to_string(i) + "]"));
        return chain_poses(ms, scales);
      },
      "motions"_a, "scales"_a = std::vector<double>{},
      "Camera-to-world poses [N+1,4,4] float64 (the first the identity, KITTI's pose files) from N motions [4,4]\n"
      "(frame i's camera -> frame i+1's: relative_pose(), FlowParts.motion), each step's translation times scales[i].");

  m.def(
      "smooth_road_scales", &smooth_road_scales, "road_scales"_a,
      "Model.sequence_scales() from each frame's Model.road_scale() (0: no road), for a sequence read frame by frame.");

  py::class_<FrameSource>(m, "FrameSource",
                          "A sequence's frames read as they are needed (geo.io.Frames): for Model.run_sequence and\n"
                          "Model.sequence_scales.");

  py::class_<ModelSpec>(m, "ModelSpec", "What a model expects and has (read from its file).")
      .def_readonly("height", &ModelSpec::height)
      .def_readonly("width", &ModelSpec::width)
      .def_readonly("seq_length", &ModelSpec::seq_length)
      .def_readonly("encoder_depth", &ModelSpec::encoder_depth)
      .def_readonly("feature_refinement", &ModelSpec::feature_refinement)
      .def_readonly("has_flow", &ModelSpec::has_flow)
      .def_readonly("source", &ModelSpec::source)
      .def_readonly("learns_intrinsics", &ModelSpec::learns_intrinsics)
      .def_readonly("precision", &ModelSpec::precision)
      .def("__repr__", [](const ModelSpec& s) {
        return "ModelSpec(" + std::to_string(s.height) + "x" + std::to_string(s.width) +
               ", seq_length=" + std::to_string(s.seq_length) + ", resnet" + std::to_string(s.encoder_depth) +
               (s.feature_refinement ? ", FR" : "") + (s.has_flow ? ", FlowNet" : "") +
               (s.learns_intrinsics ? ", learned camera" : "") + ", " + s.precision + ", '" + s.source + "')";
      });

  py::class_<Model::FlowParts>(
      m, "FlowParts",
      "flow_parts(): the full flow, the rigid flow of depth and motion alone, and that depth (of from_)\n"
      "and motion (from_ -> to); unpacks as full, rigid.")
      .def_readonly("full", &Model::FlowParts::full)
      .def_readonly("rigid", &Model::FlowParts::rigid)
      .def_readonly("depth", &Model::FlowParts::depth)
      .def_readonly("motion", &Model::FlowParts::motion)
      .def("__iter__", [](const Model::FlowParts& p) { return py::iter(py::make_tuple(p.full, p.rigid)); });

  py::class_<Model>(m, "Model",
                    "A trained geo model: depth, camera motion and optical flow of images.\n"
                    "Images are torch tensors [3,H,W] / [B,3,H,W] or numpy arrays [H,W,3] / [B,H,W,3] (RGB, uint8\n"
                    "0..255 or float 0..1), any size; outputs are torch tensors at the images' size. Intrinsics\n"
                    "([3,3], pixels of the given image) are optional (KITTI's proportions, or the camera a model\n"
                    "that learns it predicts). Safe to call from several threads at once.")
      .def_static(
          "load",
          [](const std::string& path, const std::string& device, const std::string& precision, int threads,
             const py::object& calibration, bool keep_float_weights) {
            const LoadOptions options = load_options(device, precision, threads, calibration, keep_float_weights);
            py::gil_scoped_release release;
            return Model::load(path, options);
          },
          "path"_a, py::kw_only(), "device"_a = "cpu", "precision"_a = "fp32", "threads"_a = 0,
          "calibration"_a = py::none(), "keep_float_weights"_a = true,
          "A geo_export model file, a training checkpoint or a run folder. device: cpu, cuda, cuda:N or auto;\n"
          "precision: fp32, bf16, auto or int8 (CPU; calibration: a few frames like those the model will see, in\n"
          "order: see quantize_int8; keep_float_weights: see quantize_int8); threads > 0 sets LibTorch's\n"
          "intra-op threads (process-wide).")
      .def_static(
          "create",
          [](const std::string& config_yaml, const std::string& device, const std::string& precision, int threads,
             const py::object& calibration, bool keep_float_weights) {
            const LoadOptions options = load_options(device, precision, threads, calibration, keep_float_weights);
            py::gil_scoped_release release;
            return Model::create(config_yaml, options);
          },
          "config_yaml"_a = "{}", py::kw_only(), "device"_a = "cpu", "precision"_a = "fp32", "threads"_a = 0,
          "calibration"_a = py::none(), "keep_float_weights"_a = true,
          "Untrained networks (torch.manual_seed first for fixed weights) of a geo config given as YAML text\n"
          "(model.*, data.height/width/seq_length, loss.*; absent keys: geo's defaults, \"{}\": the paper's model\n"
          "at 128x416): for measuring speed or trying a program before a model is trained.")
      .def(
          "quantize_int8",
          [](Model& model, const py::sequence& frames, bool keep_float_weights) {
            const auto xs = images_arg(frames, "frames");
            py::gil_scoped_release release;
            model.quantize_int8(xs, keep_float_weights);
          },
          "frames"_a = py::list(), py::kw_only(), "keep_float_weights"_a = true,
          "Switches this fp32 CPU model to int8: the DepthNet, PoseNet and FlowNet calibrated on frames (like\n"
          "those the model will see, in order; consecutive pairs calibrate the FlowNet and PoseNet); without\n"
          "frames, with the calibration its file keeps (has_int8_calibration). keep_float_weights=False: for\n"
          "inference only, the float kernels go as the int8 ones are made (~3/4 less memory); the model runs\n"
          "in int8 only and save() writes an int8 model file (its int8 kernels: opens in int8 only, at once).\n"
          "Not while another thread uses the model.")
      .def_property_readonly("float_weights_released", &Model::float_weights_released)
      .def_property_readonly("has_int8_calibration", &Model::has_int8_calibration,
                             "Whether the file keeps an int8 calibration (geo_export --int8, or save() after\n"
                             "quantize_int8): quantize_int8() then needs no frames.")
      .def_property_readonly("spec", &Model::spec)
      .def_property_readonly("device", &Model::device)
      .def_property_readonly("training_configs", &Model::training_configs,
                             "The YAML configs the weights were trained with: the checkpoint's own, then those of the\n"
                             "checkpoints its training started from (--init), nearest first; [] for geo_export files.")
      .def(
          "depth",
          [](const Model& model, py::handle image) {
            const auto x = image_arg(image, "image");
            py::gil_scoped_release release;
            return model.depth(x);
          },
          "image"_a, "Depth (up to scale) at the image's size: [H,W] ([B,H,W] for a batch).")
      .def(
          "metric_depth",
          [](const Model& model, py::handle image, double camera_height, py::handle intrinsics, bool return_scale) {
            const auto x = image_arg(image, "image");
            const auto K = optional_tensor_arg(intrinsics, "intrinsics");
            std::vector<double> scale;
            torch::Tensor depth;
            {
              py::gil_scoped_release release;
              depth = model.metric_depth(x, camera_height, K, &scale);
            }
            return with_scale(depth, scale, return_scale);
          },
          "image"_a, "camera_height"_a = 1.65, "intrinsics"_a = py::none(), py::kw_only(), "return_scale"_a = false,
          "Depth in metres from the camera's height above the road (KITTI: 1.65 m) fitted to the lower image;\n"
          "return_scale: also the factor(s) applied. geo.Error when no road is found.")
      .def(
          "relative_pose",
          [](const Model& model, py::handle from, py::handle to, py::handle intrinsics) {
            const auto a = image_arg(from, "from"), b = image_arg(to, "to");
            const auto K = optional_tensor_arg(intrinsics, "intrinsics");
            py::gil_scoped_release release;
            return model.relative_pose(a, b, K);
          },
          "from_"_a, "to"_a, "intrinsics"_a = py::none(),
          "[4,4] transform of points in from_'s camera into to's (translation up to the depth's scale).")
      .def(
          "metric_relative_pose",
          [](const Model& model, py::handle from, py::handle to, double camera_height, py::handle intrinsics,
             bool return_scale) {
            const auto a = image_arg(from, "from"), b = image_arg(to, "to");
            const auto K = optional_tensor_arg(intrinsics, "intrinsics");
            std::vector<double> scale;
            torch::Tensor pose;
            {
              py::gil_scoped_release release;
              pose = model.metric_relative_pose(a, b, camera_height, K, &scale);
            }
            return with_scale(pose, scale, return_scale);
          },
          "from_"_a, "to"_a, "camera_height"_a = 1.65, "intrinsics"_a = py::none(), py::kw_only(),
          "return_scale"_a = false, "relative_pose() with its translation in metres (metric_depth()'s scale of from_).")
      .def(
          "pose",
          [](const Model& model, const py::sequence& frames) {
            const auto xs = images_arg(frames, "frames");
            py::gil_scoped_release release;
            return model.pose(xs);
          },
          "frames"_a,
          "The PoseNet on a snippet of spec.seq_length frames: [L-1,4,4] from the middle frame's camera into each "
          "other's.")
      .def(
          "flow",
          [](const Model& model, py::handle from, py::handle to, py::handle intrinsics, py::handle previous) {
            const auto x = pair_args(from, to, intrinsics, previous);
            py::gil_scoped_release release;
            return model.flow(x.from, x.to, x.intrinsics, x.previous);
          },
          "from_"_a, "to"_a, "intrinsics"_a = py::none(), "previous"_a = py::none(),
          "Optical flow from_ -> to in pixels: [2,H,W] (rigid flow plus the FlowNet's residual).")
      .def(
          "flow_parts",
          [](const Model& model, py::handle from, py::handle to, py::handle intrinsics, py::handle previous) {
            const auto x = pair_args(from, to, intrinsics, previous);
            py::gil_scoped_release release;
            return model.flow_parts(x.from, x.to, x.intrinsics, x.previous);
          },
          "from_"_a, "to"_a, "intrinsics"_a = py::none(), "previous"_a = py::none(),
          "flow() and the rigid flow alone: FlowParts(full, rigid), which unpacks as full, rigid = ...")
      .def(
          "intrinsics",
          [](const Model& model, py::handle from, py::handle to) {
            const auto a = image_arg(from, "from"), b = image_arg(to, "to");
            py::gil_scoped_release release;
            return model.intrinsics(a, b);
          },
          "from_"_a, "to"_a, "The camera a model that learns it predicts for the pair: [3,3] in pixels of the images.")
      .def(
          "sequence_scales",
          [](const Model& model, py::handle frames, double camera_height, py::handle intrinsics,
             bool return_without_road) {
            std::optional<TensorFrames> held;
            auto& source = frames_arg(frames, held);
            const auto K = optional_tensor_arg(intrinsics, "intrinsics");
            std::vector<size_t> without;
            std::vector<double> scales;
            {
              py::gil_scoped_release release;
              scales = model.sequence_scales(source, camera_height, K, &without);
            }
            if (!return_without_road) return py::cast(scales);
            return py::object(py::make_tuple(scales, without));
          },
          "frames"_a, "camera_height"_a = 1.65, "intrinsics"_a = py::none(), py::kw_only(),
          "return_without_road"_a = false,
          "Metres per unit of depth of each frame of a sequence (a list of images or a geo.io.Frames): "
          "metric_depth()'s\n"
          "factor smoothed over 11 frames (frames without a road take their neighbours'); return_without_road: also\n"
          "those frames' indices.")
      .def(
          "run_sequence",
          [](const Model& model, py::handle frames, py::object callback, std::vector<double> scales,
             py::handle intrinsics) {
            std::optional<TensorFrames> held;
            auto& source = frames_arg(frames, held);
            const auto K = optional_tensor_arg(intrinsics, "intrinsics");
            std::vector<torch::Tensor> depth, flow, rigid, motion;
            const auto as_dict = [](const SequenceFrame& f) {
              py::dict d("index"_a = f.index, "image"_a = f.image, "depth"_a = f.depth, "scale"_a = f.scale);
              for (const auto& [key, t] :
                   {std::pair{"flow", &f.flow}, std::pair{"rigid_flow", &f.rigid_flow}, std::pair{"motion", &f.motion}})
                d[key] = t->defined() ? py::cast(*t) : py::none();
              return d;
            };
            torch::Tensor poses;
            {
              py::gil_scoped_release release;
              poses = model.run_sequence(
                  source,
                  [&](const SequenceFrame& f) {
                    if (!callback.is_none()) {
                      py::gil_scoped_acquire acquire;
                      callback(as_dict(f));
                      return;
                    }
                    depth.push_back(f.depth);
                    if (!f.flow.defined()) return;
                    flow.push_back(f.flow), rigid.push_back(f.rigid_flow), motion.push_back(f.motion);
                  },
                  scales, K);
            }
            const auto stacked = [](const std::vector<torch::Tensor>& ts) {
              return ts.empty() ? py::object(py::none()) : py::cast(torch::stack(ts));
            };
            py::dict out("poses"_a = poses.defined() ? py::cast(poses) : py::none());
            if (callback.is_none()) {
              out["depth"] = stacked(depth), out["flow"] = stacked(flow), out["rigid_flow"] = stacked(rigid);
              out["motion"] = stacked(motion);
            }
            return out;
          },
          "frames"_a, "callback"_a = py::none(), py::kw_only(), "scales"_a = std::vector<double>{},
          "intrinsics"_a = py::none(),
          "A whole sequence as geo_infer runs it (a list of images, or a geo.io.Frames read as needed: three frames\n"
          "held at a time): each frame's depth (times scales[i], e.g. sequence_scales(); none: 1) and, to the next\n"
          "frame, the flow (full and rigid) and the motion [4,4], each network once per frame. With callback, each\n"
          "frame's dict (index, image, depth, scale, flow, rigid_flow, motion; None for the last frame's) goes to\n"
          "it as it is computed and the result holds only poses; else the result also holds depth [N,H,W], flow and\n"
          "rigid_flow [N-1,2,H,W], motion [N-1,4,4]. poses: the trajectory [N,4,4] float64 (geo_infer's\n"
          "trajectory.txt), None for one frame or a 5-frame model.")
      .def(
          "road_scale",
          [](const Model& model, py::handle frame, double camera_height, py::handle intrinsics) {
            const auto x = image_arg(frame, "frame");
            const auto K = optional_tensor_arg(intrinsics, "intrinsics");
            py::gil_scoped_release release;
            return model.road_scale(x, camera_height, K);
          },
          "frame"_a, "camera_height"_a = 1.65, "intrinsics"_a = py::none(),
          "One frame's own factor (metric_depth()'s), 0 where no road plane is found: for a sequence too long to\n"
          "hold, frame by frame, then geo.smooth_road_scales() gives what sequence_scales() gives.")
      .def(
          "save",
          [](const Model& model, const std::string& path, bool half, bool force) {
            py::gil_scoped_release release;
            model.save(path, half, force);
          },
          "path"_a, "half"_a = false, "force"_a = false,
          "Writes the weights and spec (geo_export's file); half: stored as float16. Refuses the file the model\n"
          "was loaded from and, unless force, an existing file that is not a model file (a training checkpoint).")
      .def("__repr__", [](const Model& model) { return "geo.Model('" + model.spec().source + "')"; });
}

}  // namespace geo::python
