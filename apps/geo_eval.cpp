// geo_eval: the published evaluation protocols (Eigen et al. 2014 as in GeoNet's kitti_eval) on KITTI or a geo_synth world.
//   geo_eval --split eigen     --data-root <kitti_raw>  --checkpoint <ckpt | run folder>
//   geo_eval --split kitti2015 --data-root <kitti2015>  --checkpoint <ckpt>
//   geo_eval --split odometry  --data-root <odometry>   --sequence 09 --checkpoint <ckpt>
//   geo_eval --split eigen --predictions depths.npy|folder     (precomputed predictions)
//   geo_eval ... --precision int8 --calibration FRAMES         (the model in int8, calibrated on FRAMES)
//   geo_eval ... --checkpoint model_int8.pt --precision int8   (a geo_export --int8 file, its own calibration)
//   geo_eval --compare a.json b.json                           (side-by-side table)
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <filesystem>

#include "core/files.h"
#include "eval/protocols.h"
#include "app_options.h"

namespace {

// geo_eval's command line.
struct EvalCommand {
  geo::EvalOptions eval;
  std::string checkpoint, output, device = "auto", runs = "runs", predictions, untrained, export_gt;
  std::string scaling = "median", flow_resize = "nearest", precision = "fp32", calibration;
  int64_t calibration_frames = 8;
  bool trivial = false, exact_pixels = false;
  std::vector<std::string> compare;
};

void add_options(CLI::App& app, EvalCommand& c) {
  geo::EvalOptions& o = c.eval;
  app.footer(
      "Data root: --data-root, else $GEO_KITTI_ROOT, else ./data/kitti. For a geo_synth world give its root;\n"
      "the split's folder (raw/, kitti2015/, odometry/) is found inside.\n"
      "Model: --checkpoint (a .pt file or a run folder: the best checkpoint of its last stage, else its latest),\n"
      "else the newest run under ./runs. --export-gt DIR alone writes the Eigen ground truth without a model.\n"
      "Predictions (--predictions): eigen = folder of 16-bit PNGs (depth x 256) named %06d.png by line of\n"
      "the split file, or one float32 .npy [N,H,W]; kitti2015 = folder of KITTI flow PNGs named like the\n"
      "ground truth (000123_10.png); odometry = one KITTI pose file (3x4 camera-to-world a line, frame 0 first).\n"
      "Eigen protocol: Velodyne ground truth (pixel = round(x/z) - 1, depth = Velodyne x, nearest point kept),\n"
      "prediction resized bilinearly, 1e-3 < gt < 80, Garg crop, per-image median scaling, clamp [1e-3, 80].");
  auto* split_opt = app.add_option("--split", o.split, "eigen, kitti2015 or odometry")
                        ->check(CLI::IsMember({"eigen", "kitti2015", "odometry"}));
  app.add_option("--data-root", o.data_root, "dataset root (default: $GEO_KITTI_ROOT, else ./data/kitti)");
  auto* checkpoint_opt =
      app.add_option("--checkpoint", c.checkpoint, "checkpoint file or run folder (default: newest run in --runs)");
  app.add_option("--runs", c.runs, "where to look for the newest run when --checkpoint is not given");
  auto* predictions_opt =
      app.add_option("--predictions", c.predictions, "evaluate precomputed predictions instead of a model");
  auto* untrained_opt =
      app.add_option("--untrained", c.untrained, "evaluate an untrained model of this config (baseline)");
  auto* trivial_opt =
      app.add_flag("--trivial", c.trivial, "evaluate the trivial baseline: constant depth, zero flow, zero motion");
  // One source of predictions: a model, a predictions file, an untrained model or the trivial baseline.
  trivial_opt->excludes(checkpoint_opt)->excludes(predictions_opt)->excludes(untrained_opt);
  untrained_opt->excludes(checkpoint_opt)->excludes(predictions_opt);
  predictions_opt->excludes(checkpoint_opt);
  app.add_option("--split-file", o.split_file,
                 "subset or order: image paths, 'folder frame side' lines or flow pair paths");
  app.add_option("--sequence", o.sequence, "odometry sequence (default 09)");
  app.add_option("--output", c.output, "write the results as JSON here");
  app.add_option("--output-poses", o.output_poses, "odometry: write the predicted trajectory (KITTI pose file)");
  app.add_option("--scaling", c.scaling,
                 "eigen: depth scale per image from median(gt)/median(pred) (the papers'), from the camera's height "
                 "above the road fitted to the prediction (no ground truth), or none; odometry: camera-height also "
                 "scores the trajectory in metres (metric_t_err, metric_r_err, metric_scale_error)")
      ->check(CLI::IsMember({"median", "camera-height", "none"}));
  app.add_option(
         "--camera-height", o.camera_height,
         "eigen, odometry: the camera's height above the road in metres (default: the data root's camera_height.txt, "
         "which geo_synth writes, else KITTI's 1.65)")
      ->check(geo::app::above_zero());
  app.add_option(
         "--segment-lengths", o.segment_lengths,
         "odometry: segment lengths in metres of KITTI's t_err (%) and r_err (deg/100 m) (default 100 200 ... 800)")
      ->expected(1, -1)
      ->check(geo::app::above_zero());
  app.add_option("--export-gt", c.export_gt, "eigen: write the ground-truth depth maps (uint16 PNG, depth x 256)");
  geo::app::add_device_option(app, c.device, "default: auto");
  geo::app::add_precision_option(
      app, c.precision, {"fp32", "bf16", "auto", "int8"},
      "what the model computes in: fp32 (default), bf16, auto (bf16 on CPUs with AVX512-BF16/AMX) "
      "or int8 (CPU; calibrated on --calibration, or with the calibration a geo_export --int8 file keeps): its "
      "accuracy against fp32's");
  geo::app::add_calibration_options(app, c.calibration, c.calibration_frames, "--precision int8");
  app.add_option("--flow-resize", c.flow_resize,
                 "kitti2015: resize predicted flow to the ground truth by nearest (GeoNet) or bilinear")
      ->check(CLI::IsMember({"nearest", "bilinear"}));
  app.add_flag("--exact-pixels", c.exact_pixels,
               "eigen: project Velodyne points without the reference code's -1 pixel shift");
  auto* compare_opt =
      app.add_option("--compare", c.compare, "print these results JSON files side by side and exit")->expected(1, -1);
  // --compare only reads results: every option of an evaluation would be silently ignored beside it.
  for (auto* other : {split_opt, checkpoint_opt, predictions_opt, untrained_opt, trivial_opt})
    compare_opt->excludes(other);
}

// --compare: earlier results side by side, columns named by file stem (trained.json -> trained).
int compare(const std::vector<std::string>& files) {
  std::vector<geo::EvalResult> results;
  std::vector<std::string> names;
  for (const auto& f : files) {
    results.push_back(geo::read_result(f));
    names.push_back(std::filesystem::path(f).stem().string());
  }
  std::printf("%s", geo::format_results(results, names).c_str());
  return 0;
}

int evaluate(EvalCommand& c) {
  geo::EvalOptions& o = c.eval;
  o.matlab_offset = !c.exact_pixels;
  o.scaling = geo::depth_scaling_named(c.scaling);
  o.flow_resize = geo::flow_resize_named(c.flow_resize);
  geo::check_eval_options(o);
  o.data_root = geo::eval_data_root(o.data_root);
  // The source of the predictions: a model (a checkpoint, an untrained network), files, or the
  // trivial baseline; none with --export-gt alone.
  geo::SourceChoice choice;
  choice.checkpoint = c.checkpoint, choice.runs = c.runs, choice.predictions = c.predictions;
  choice.untrained_config = c.untrained, choice.device = c.device, choice.trivial = c.trivial;
  choice.precision = c.precision, choice.calibration = c.calibration, choice.calibration_frames = c.calibration_frames;
  choice.need_model = c.export_gt.empty();
  const auto chosen = geo::choose_source(choice);
  // Before minutes of evaluation: the outputs replace nothing this command reads (the model, the
  // predictions, the split file, the calibration frames, the data root's ground truth) and not each other.
  auto reads = geo::evaluation_reads(choice, chosen, o.split_file);
  reads.push_back(o.data_root);
  geo::check_outputs({{"--output", c.output}, {"--output-poses", o.output_poses}, {"--export-gt", c.export_gt}}, reads);
  geo::EvalResult r;
  if (!c.export_gt.empty()) {
    if (o.split != "eigen") throw std::runtime_error("--export-gt is for --split eigen (got " + o.split + ")");
    r = geo::export_eigen_ground_truth(o, c.export_gt);
    spdlog::info("ground truth of {} test images written to {}", r.counts[0].second, c.export_gt);
  }
  if (chosen.source) {
    spdlog::info("evaluating split {} on {}", o.split, geo::split_root(o.split, o.data_root));
    r = geo::evaluate(o, *chosen.source);
  }
  std::printf("%s", geo::format_results({r}, {o.split}).c_str());
  if (!c.output.empty()) {
    geo::write_file_atomic(c.output, r.json());
    spdlog::info("results written to {}", c.output);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return geo::app::run_command<EvalCommand>(
      argc, argv, "geo_eval: depth (Eigen split), optical flow (KITTI 2015) and pose (KITTI odometry) metrics",
      add_options, [](EvalCommand& c) { return c.compare.empty() ? evaluate(c) : compare(c.compare); });
}
