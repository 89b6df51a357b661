// geo_eval: the published evaluation protocols (Eigen et al. 2014 as in GeoNet's kitti_eval) on KITTI or a geo_synth world.
//   geo_eval --split eigen     --data-root <kitti_raw>  --checkpoint <ckpt | run folder>
//   geo_eval --split kitti2015 --data-root <kitti2015>  --checkpoint <ckpt>
//   geo_eval --split odometry  --data-root <odometry>   --sequence 09 --checkpoint <ckpt>
//   geo_eval --split eigen --predictions depths.npy|folder     (precomputed predictions)
//   geo_eval --compare a.json b.json                           (side-by-side table)
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include <cstdio>
#include <filesystem>

#include "core/files.h"
#include "core/logging.h"
#include "eval/protocols.h"
#include "app_options.h"

int main(int argc, char** argv) {
  CLI::App app{"geo_eval: depth (Eigen split), optical flow (KITTI 2015) and pose (KITTI odometry) metrics"};
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
  geo::EvalOptions o;
  std::string checkpoint, output, device = "auto", runs = "runs", predictions, export_gt;
  bool trivial = false;
  std::vector<std::string> compare;
  bool no_matlab = false;
  auto* split_opt = app.add_option("--split", o.split, "eigen, kitti2015 or odometry")->check(CLI::IsMember({"eigen", "kitti2015", "odometry"}));
  app.add_option("--data-root", o.data_root, "dataset root (default: $GEO_KITTI_ROOT, else ./data/kitti)");
  auto* checkpoint_opt = app.add_option("--checkpoint", checkpoint, "checkpoint file or run folder (default: newest run in --runs)");
  app.add_option("--runs", runs, "where to look for the newest run when --checkpoint is not given");
  auto* predictions_opt = app.add_option("--predictions", predictions, "evaluate precomputed predictions instead of a model");
  std::string untrained;
  auto* untrained_opt = app.add_option("--untrained", untrained, "evaluate an untrained model of this config (baseline)");
  auto* trivial_opt = app.add_flag("--trivial", trivial, "evaluate the trivial baseline: constant depth, zero flow, zero motion");
  // One source of predictions: a model, a predictions file, an untrained model or the trivial baseline.
  trivial_opt->excludes(checkpoint_opt)->excludes(predictions_opt)->excludes(untrained_opt);
  untrained_opt->excludes(checkpoint_opt)->excludes(predictions_opt);
  predictions_opt->excludes(checkpoint_opt);
  app.add_option("--split-file", o.split_file, "subset or order: image paths, 'folder frame side' lines or flow pair paths");
  app.add_option("--sequence", o.sequence, "odometry sequence (default 09)");
  app.add_option("--output", output, "write the results as JSON here");
  app.add_option("--output-poses", o.output_poses, "odometry: write the predicted trajectory (KITTI pose file)");
  std::string scaling = "median";
  app.add_option("--scaling", scaling,
                 "eigen: depth scale per image from median(gt)/median(pred) (the papers'), from the camera's height "
                 "above the road fitted to the prediction (no ground truth), or none; odometry: camera-height also "
                 "scores the trajectory in metres (metric_t_err, metric_r_err, metric_scale_error)")
      ->check(CLI::IsMember({"median", "camera-height", "none"}));
  app.add_option("--camera-height", o.camera_height,
                 "eigen, odometry: the camera's height above the road in metres (default: the data root's camera_height.txt, "
                 "which geo_synth writes, else KITTI's 1.65)")
      ->check(geo::app::above_zero());
  app.add_option("--segment-lengths", o.segment_lengths,
                 "odometry: segment lengths in metres of KITTI's t_err (%) and r_err (deg/100 m) (default 100 200 ... 800)")
      ->expected(1, -1)
      ->check(geo::app::above_zero());
  app.add_option("--export-gt", export_gt, "eigen: write the ground-truth depth maps (uint16 PNG, depth x 256)");
  geo::app::add_device_option(app, device, "default: auto");
  std::string flow_resize = "nearest";
  app.add_option("--flow-resize", flow_resize, "kitti2015: resize predicted flow to the ground truth by nearest (GeoNet) or bilinear")
      ->check(CLI::IsMember({"nearest", "bilinear"}));
  app.add_flag("--exact-pixels", no_matlab, "eigen: project Velodyne points without the reference code's -1 pixel shift");
  auto* compare_opt = app.add_option("--compare", compare, "print these results JSON files side by side and exit")->expected(1, -1);
  // --compare only reads results: every option of an evaluation would be silently ignored beside it.
  for (auto* other : {split_opt, checkpoint_opt, predictions_opt, untrained_opt, trivial_opt}) compare_opt->excludes(other);
  CLI11_PARSE(app, argc, argv);
  return geo::app::run_tool([&] {
    if (!compare.empty()) {
      std::vector<geo::EvalResult> results;
      std::vector<std::string> names;  // columns named by file stem: trained.json -> trained
      for (const auto& f : compare) {
        results.push_back(geo::read_result(f));
        names.push_back(std::filesystem::path(f).stem().string());
      }
      std::printf("%s", geo::format_results(results, names).c_str());
      return 0;
    }
    o.matlab_offset = !no_matlab;
    o.scaling = geo::depth_scaling_named(scaling);
    o.flow_resize = geo::flow_resize_named(flow_resize);
    geo::check_eval_options(o);
    o.data_root = geo::eval_data_root(o.data_root);
    // The source of the predictions: a model (a checkpoint, an untrained network), files, or the
    // trivial baseline; none with --export-gt alone.
    geo::SourceChoice choice;
    choice.checkpoint = checkpoint, choice.runs = runs, choice.predictions = predictions;
    choice.untrained_config = untrained, choice.device = device, choice.trivial = trivial;
    choice.need_model = export_gt.empty();
    const auto chosen = geo::choose_source(choice);
    // Before minutes of evaluation: the outputs replace nothing this command reads (the model, the
    // predictions, the data root's ground truth) and not each other.
    geo::check_outputs({{"--output", output}, {"--output-poses", o.output_poses}},
                       {chosen.reads, checkpoint, o.data_root});
    geo::EvalResult r;
    if (!export_gt.empty()) {
      if (o.split != "eigen") throw std::runtime_error("--export-gt is for --split eigen (got " + o.split + ")");
      r = geo::export_eigen_ground_truth(o, export_gt);
      spdlog::info("ground truth of {} test images written to {}", r.counts[0].second, export_gt);
    }
    if (chosen.source) {
      spdlog::info("evaluating split {} on {}", o.split, geo::split_root(o.split, o.data_root));
      r = geo::evaluate(o, *chosen.source);
    }
    std::printf("%s", geo::format_results({r}, {o.split}).c_str());
    if (!output.empty()) {
      geo::write_file_atomic(output, r.json());
      spdlog::info("results written to {}", output);
    }
    return 0;
  });
}
