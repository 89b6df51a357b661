// geo.eval.evaluate (geo_eval's protocols on KITTI-format folders) and geo.io (image, depth and flow
// files in KITTI's formats): the parts that read images, built with OpenCV.
#include "bindings.h"

#include "core/files.h"
#include "data/cv_tensor.h"
#include "data/image_io.h"
#include "data/video/frame_stream.h"
#include "eval/protocols.h"
#include "geo/geo.h"

#include <filesystem>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace geo::python {

using namespace pybind11::literals;

namespace {

// geo.io.Frames: a FrameStream's frames at the size asked for, as geo_infer's reader gives them.
class StreamFrames : public FrameSource {
 public:
  StreamFrames(std::string path, std::optional<std::pair<int64_t, int64_t>> size, int64_t max_frames)
      : path_(std::move(path)), size_(size), max_frames_(max_frames) {
    if (size_ && (size_->first < 1 || size_->second < 1))
      throw Error("geo.io.Frames: size must be (height, width) of at least 1, got (" + std::to_string(size_->first) +
                  ", " + std::to_string(size_->second) + ")");
    if (max_frames_ < 0)
      throw Error("geo.io.Frames: max_frames must be >= 0 (0: all), got " + std::to_string(max_frames_));
    restart();  // opens it now: a missing path is an error here
  }
  bool next(torch::Tensor& frame) override {
    if (max_frames_ > 0 && static_cast<int64_t>(read_) >= max_frames_) return false;
    cv::Mat m;
    std::string name;
    if (!stream_->next(name, &m)) return false;
    const std::string what = path_ + " [" + name + "]";
    frame = size_ ? resized_mat_to_frame(m, size_->first, size_->second, what)
                  : resized_mat_to_frame(m, m.rows, m.cols, what);
    if (read_ == names_.size()) names_.push_back(name);
    ++read_;
    return true;
  }
  void restart() override {
    stream_.emplace(path_, "frames");
    read_ = 0;
  }
  const std::vector<std::string>& names() const { return names_; }

 private:
  std::string path_;
  std::optional<std::pair<int64_t, int64_t>> size_;
  int64_t max_frames_;
  std::optional<FrameStream> stream_;
  size_t read_ = 0;
  std::vector<std::string> names_;
};

py::object evaluate_split(const std::string& split, const std::string& data_root, const std::string& checkpoint,
                          const std::string& predictions, bool trivial, const std::string& split_file,
                          const std::string& sequence, const std::string& scaling, double camera_height,
                          const std::string& flow_resize, bool exact_pixels, const std::string& device,
                          const std::string& precision, const std::string& calibration, int64_t calibration_frames,
                          const std::string& output) {
  EvalOptions o;
  o.split = split, o.split_file = split_file, o.sequence = sequence, o.camera_height = camera_height;
  o.matlab_offset = !exact_pixels;
  o.scaling = depth_scaling_named(scaling);
  o.flow_resize = flow_resize_named(flow_resize);
  check_eval_options(o);
  if (trivial + !checkpoint.empty() + !predictions.empty() != 1)
    throw Error("give one source of predictions: checkpoint=, predictions= or trivial=True");
  std::string json;
  {
    py::gil_scoped_release release;
    o.data_root = eval_data_root(data_root);
    SourceChoice choice;
    choice.checkpoint = checkpoint, choice.predictions = predictions, choice.trivial = trivial, choice.device = device;
    choice.precision = precision, choice.calibration = calibration, choice.calibration_frames = calibration_frames;
    const auto chosen = choose_source(choice);
    auto reads = evaluation_reads(choice, chosen, o.split_file);
    reads.push_back(o.data_root);
    check_outputs({{"output", output}}, reads);
    const EvalResult r = evaluate(o, *chosen.source);
    json = r.json();
    if (!output.empty()) write_file_atomic(output, json);
  }
  return py::module_::import("json").attr("loads")(json);
}

}  // namespace

void bind_eval(py::module_& m) {
  py::module_ eval = m.attr("eval");
  eval.def("evaluate", &evaluate_split, "split"_a, py::kw_only(), "data_root"_a = "", "checkpoint"_a = "",
           "predictions"_a = "", "trivial"_a = false, "split_file"_a = "", "sequence"_a = "09", "scaling"_a = "median",
           "camera_height"_a = 0.0, "flow_resize"_a = "nearest", "exact_pixels"_a = false, "device"_a = "auto",
           "precision"_a = "fp32", "calibration"_a = "", "calibration_frames"_a = 8, "output"_a = "",
           "geo_eval's protocols: split eigen (depth), kitti2015 (flow) or odometry (pose) on data_root (KITTI's\n"
           "folders or a geo_synth world; default $GEO_KITTI_ROOT, else ./data/kitti), of a checkpoint / run folder /\n"
           "model file, of predictions (files as geo_eval --predictions reads them) or of the trivial baseline.\n"
           "precision: fp32, bf16, auto or int8 (calibrated on the first calibration_frames frames of calibration, a\n"
           "folder of frames or a video), as geo_eval --precision. Returns the results as a dict (geo_eval's JSON);\n"
           "output: also write that JSON file.");
  eval.def(
      "compare",
      [](const std::vector<std::string>& files) {
        std::vector<EvalResult> results;
        std::vector<std::string> names;
        for (const auto& f : files)
          results.push_back(read_result(f)), names.push_back(std::filesystem::path(f).stem().string());
        return format_results(results, names);
      },
      "files"_a,
      "geo_eval --compare: results JSON files side by side, with a note for every difference but the model.");

  auto io = m.def_submodule("io", "Images, depth maps and flow fields in KITTI's file formats (OpenCV).");
  py::class_<StreamFrames, FrameSource>(io, "Frames",
                                        "The frames of an image, a folder of frames (natural order) or a video, read\n"
                                        "one at a time as geo_infer reads them (RGB uint8 [3,H,W], 16-bit images as\n"
                                        "float [0,1]), resized to size=(h, w) when given (the model's: geo_infer's\n"
                                        "frames); max_frames > 0: the first that many. For Model.run_sequence.")
      .def(py::init<std::string, std::optional<std::pair<int64_t, int64_t>>, int64_t>(), "path"_a,
           "size"_a = py::none(), "max_frames"_a = 0)
      .def_property_readonly(
          "names", &StreamFrames::names,
          "The frames' names (a file's name without extension; a video frame's number), as read so far "
          "(all after a pass).");
  io.def(
      "read_image",
      [](const std::string& path, std::optional<std::pair<int64_t, int64_t>> size) {
        py::gil_scoped_release release;
        return size ? read_image_resized(path, size->first, size->second) : read_image(path);
      },
      "path"_a, "size"_a = py::none(),
      "An image as float32 [3,H,W] in [0,1] RGB (grey expanded, 16-bit scaled), resized to size=(h, w) when given\n"
      "(area when shrinking, linear otherwise: as geo_infer reads frames).");
  io.def(
      "write_image", [](const std::string& path, py::handle image) { write_image(path, image_arg(image, "image")); },
      "path"_a, "image"_a, "Writes [3,H,W] (float in [0,1] or uint8) as PNG/JPEG by the file's extension.");
  io.def(
      "read_depth_png", [](const std::string& path) { return read_depth_png(path).squeeze(0); }, "path"_a,
      "A KITTI depth PNG (uint16, depth x 256, 0 = none): [H,W] float32 metres.");
  io.def(
      "write_depth_png",
      [](const std::string& path, py::handle depth) { write_depth_png(path, tensor_arg(depth, "depth")); }, "path"_a,
      "depth"_a, "Writes [H,W] depth as a KITTI depth PNG (uint16, depth x 256; geo_infer's <name>-depth.png).");
  io.def(
      "read_flow_png",
      [](const std::string& path) {
        const auto f = read_flow_png(path);
        return py::make_tuple(f.flow, f.valid[0] > 0.5);
      },
      "path"_a, "A KITTI flow PNG: (flow [2,H,W] float32 pixels, valid [H,W] bool).");
  io.def(
      "write_flow_png",
      [](const std::string& path, py::handle flow, py::handle valid) {
        auto v = optional_tensor_arg(valid, "valid");
        if (v.defined()) v = v.to(torch::kFloat32).reshape({1, v.size(-2), v.size(-1)});
        write_flow_png(path, tensor_arg(flow, "flow").to(torch::kFloat32), v);
      },
      "path"_a, "flow"_a, "valid"_a = py::none(), "Writes [2,H,W] flow (and its [H,W] validity) as a KITTI flow PNG.");
}

}  // namespace geo::python
