// The published evaluation protocols (Eigen depth, KITTI 2015 flow, SfMLearner's snippet ATE) over
// KITTI-format folders (real KITTI or a geo_synth world), of the predictions of a source
// (eval/sources.h: a model, prediction files, the trivial baseline):
//   eigen      depth on the Eigen test images, Velodyne ground truth, Garg crop, median scaling, 80 m;
//              where <drive>/obj_map/image_0X/ exists (geo_synth), AbsRel and a1 on the moving objects
//   kitti2015  flow EPE on flow_noc and flow_occ, Fl-all, over the image_2/%06d_10.png pairs; where
//              obj_map/ exists, EPE and Fl of the background and the foreground (moving objects)
//              as KITTI's devkit; for a model with a FlowNet, the same for its rigid flow alone
//              (depth and pose, metrics prefixed rigid_): what the residual flow adds
//   odometry   pose ATE over 5-frame snippets (SfMLearner formula), and the full trajectory's RMS
//              error after a Sim(3) alignment; the predicted trajectory as a KITTI pose file
#pragma once

#include "eval/metrics.h"
#include "eval/predictor.h"
#include "eval/sources.h"

#include <string>
#include <utility>
#include <vector>

namespace geo {

// How monocular depth gets its scale: per-image median(gt)/median(pred) (the papers' protocol), the
// camera's known height above the fitted road plane (no ground truth used), or none.
enum class DepthScaling { kMedian, kCameraHeight, kNone };

struct EvalOptions {
  std::string split;            // eigen | kitti2015 | odometry
  std::string data_root;        // KITTI raw / KITTI 2015 / odometry root, or a geo_synth world root
  std::string split_file;       // subset / order; default: the split's standard list or all pairs/frames
  std::string sequence = "09";  // odometry sequence
  std::string output_poses;     // odometry: write the predicted trajectory here
  bool matlab_offset = true;    // eigen: pixel = round(x/z) - 1 as in the reference code
  FlowResize flow_resize = FlowResize::kNearest;  // kitti2015: prediction -> ground-truth size (GeoNet: nearest)
  DepthScaling scaling = DepthScaling::kMedian;   // eigen
  // Metres above the road for --scaling camera-height; 0: the height the data root records
  // (<root>/camera_height.txt, which geo_synth writes), else KITTI's 1.65.
  double camera_height = 0;
  std::vector<double> segment_lengths = kKittiSegmentLengths;  // odometry: KITTI's t_err / r_err segments (m)
};

struct EvalResult {
  std::string split, source, data_root;
  std::string scaling;    // eigen: median, camera-height (at camera_height m) or none
  std::string precision;  // of a model's predictions: fp32, bf16 or int8 (none for files and baselines)
  // What of the split was scored when not all of it: "sequence 09" (odometry), "list FILE" (a
  // split file other than the standard one).
  std::string subset;
  std::vector<std::pair<std::string, double>> metrics;
  std::vector<std::pair<std::string, int64_t>> counts;
  // The KITTI raw drives the test set comes from ("2011_09_26_drive_0002"; none for a geo_synth
  // world's kitti2015/ and odometry/, whose scenes are their own), and those of them the evaluated
  // model trained or validated on (from its checkpoint's config): results on training drives.
  std::vector<std::string> test_drives, test_drives_in_training;
  std::string training_drives_unknown;  // why the model's training drives could not be told
  std::string json() const;
};

// The scaling and flow-resize names geo_eval and Python take (median | camera-height | none; nearest |
// bilinear); others throw naming the value.
DepthScaling depth_scaling_named(const std::string& name);
FlowResize flow_resize_named(const std::string& name);
// The option combinations an evaluation refuses rather than ignores: an unknown split, camera-height
// scaling of flow, a camera height without camera-height scaling.
void check_eval_options(const EvalOptions& options);

// Scores the source's predictions on options.split. Throws naming the missing/bad file.
EvalResult evaluate(const EvalOptions& options, PredictionSource& source);
// The model's own predictions (model_source).
inline EvalResult evaluate(const EvalOptions& options, Predictor& model) {
  const auto source = model_source(model);
  return evaluate(options, *source);
}

// Eigen: the ground-truth depth of each test line as <dir>/<line, 6 digits>.png (uint16, depth x
// 256, 0 where there is none) at the test image's size, as the protocol projects it.
EvalResult export_eigen_ground_truth(const EvalOptions& options, const std::string& dir);

// "<root>/raw", "<root>/kitti2015" or "<root>/odometry" when `root` is a geo_synth world, else root.
std::string split_root(const std::string& split, const std::string& root);

// One table, one column per result, with the number each column scored (images, pairs, snippets),
// and a note for every way the columns differ other than the model (split, data root, scaling,
// subset, precision, counts, training-drive leaks): results side by side are compared, unlike ones must say so.
std::string format_results(const std::vector<EvalResult>& results, const std::vector<std::string>& names);

// Reads a results JSON written by EvalResult::json(); any other file (JSON or not) is an error naming it.
EvalResult read_result(const std::string& path);

}  // namespace geo
