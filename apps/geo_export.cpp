// geo_export: a deployable model file from a training checkpoint or run folder: the networks'
// weights and what is needed to use them (input size, sequence length, architecture, the FlowNet
// input's settings), without the optimiser state and the training config. geo::Model::load (and so
// geo_infer and any program on include/geo/geo.h) reads it; BatchNorm is folded when loaded.
//   geo_export --checkpoint runs/stage2 --out model.pt [--half]
#include <CLI/CLI.hpp>

#include <filesystem>

#include "app_options.h"
#include "open_model.h"
#include "geo/geo.h"
#include "core/files.h"
#include "pipeline/checkpoint.h"
#ifdef GEO_EXPORT_FRAMES
#include "data/video/frame_stream.h"
#endif

namespace fs = std::filesystem;

namespace {

struct ExportCommand {
  std::string checkpoint, out, calibration;
  int64_t calibration_frames = 8;
  bool half = false, force = false, int8 = false;
};

void add_options(CLI::App& app, ExportCommand& c) {
  app.add_option("--checkpoint", c.checkpoint, "checkpoint file or run folder (its best checkpoint)")->required();
  app.add_option("--out", c.out, "model file to write")->required();
  app.add_flag("--force", c.force, "replace --out even when it is not a geo_export model file");
  app.add_flag("--half", c.half, "store the weights as float16 (half the size; computed in float32 when loaded)");
  app.add_flag("--int8", c.int8,
               "calibrate int8 inference on --calibration and write an int8 model file: the int8 kernels and their "
               "calibration instead of the float weights (a quarter of the size; opens in int8 only, at once: "
               "geo_infer --precision int8)");
  geo::app::add_calibration_options(app, c.calibration, c.calibration_frames, "--int8");
}

// The first `count` frames of a folder or video, at the model's size.
std::vector<torch::Tensor> calibration_frames(const ExportCommand& c, const geo::ModelSpec& s) {
#ifdef GEO_EXPORT_FRAMES
  return geo::first_frames(c.calibration, c.calibration_frames, s.height, s.width, "--calibration");
#else
  (void)s;
  throw std::runtime_error("--calibration '" + c.calibration +
                           "': this geo_export was built without OpenCV and reads "
                           "no frames (calibrate with geo::Model::quantize_int8 and save from C++ or Python)");
#endif
}

int export_model(const ExportCommand& c) {
  if (c.int8 && c.calibration.empty())
    throw std::runtime_error("--int8 needs --calibration FRAMES (a folder or a video)");
  if (!c.int8 && !c.calibration.empty())
    throw std::runtime_error("--calibration calibrates int8: it needs --int8 (or it would be ignored)");
  geo::Model model = geo::app::open_model(c.checkpoint);
  const auto& s = model.spec();
  geo::check_model_file_target("--out", c.out, s.source, c.force);
  geo::check_outputs({{"--out", c.out}}, {s.source, c.calibration}, true);  // the checkpoint file, not its run folder
  if (c.int8) {
    const auto frames = calibration_frames(c, s);
    model.quantize_int8(frames, /*keep_float_weights=*/false);  // saved as its int8 kernels
    spdlog::info("int8: calibrated on {} frame(s) of {}", frames.size(), c.calibration);
  }
  model.save(c.out, c.half, c.force);
  // Check what was written: the same depth from both on a fixed image.
  geo::LoadOptions as_written;
  as_written.precision = c.int8 ? "int8" : "fp32";
  const geo::Model back = geo::app::open_model(c.out, as_written);
  auto image = torch::linspace(0, 1, 3 * s.height * s.width).view({3, s.height, s.width});
  const double diff = (model.depth(image) - back.depth(image)).abs().max().item<double>();
  const double scale = model.depth(image).abs().max().item<double>();
  const auto in_size = fs::file_size(s.source), out_size = fs::file_size(c.out);
  spdlog::info("{} -> {}: {}x{} input, {}-frame PoseNet, ResNet-{}, FR {}, FlowNet {}, {} weights", s.source, c.out,
               s.height, s.width, s.seq_length, s.encoder_depth, s.feature_refinement ? "on" : "off",
               s.has_flow ? "yes" : "no", c.int8 ? std::string("int8") : std::string(c.half ? "float16" : "float32"));
  spdlog::info(
      "{:.1f} MB -> {:.1f} MB ({:.0f}%); depth from the written file differs by at most {:.3g} ({:.2g} relative)",
      static_cast<double>(in_size) / 1e6, static_cast<double>(out_size) / 1e6,
      100.0 * static_cast<double>(out_size) / static_cast<double>(in_size), diff, diff / scale);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return geo::app::run_command<ExportCommand>(
      argc, argv, "geo_export: weights-only model file (for geo::Model, geo_infer) from a geo_train checkpoint",
      add_options, export_model);
}
