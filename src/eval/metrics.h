// Evaluation metrics with the published protocols' conventions (Eigen et al. 2014 as in GeoNet's kitti_eval). LibTorch only.
#pragma once

#include <torch/torch.h>

#include <map>
#include <string>
#include <utility>
#include <vector>

namespace geo {

struct DepthErrors {
  double abs_rel = 0, sq_rel = 0, rmse = 0, rmse_log = 0, a1 = 0, a2 = 0, a3 = 0;
  int64_t pixels = 0;
  std::map<std::string, double> as_map() const;
};

// Errors over paired valid depths (1-D tensors of equal length, metres, > 0).
DepthErrors depth_errors(const torch::Tensor& gt, const torch::Tensor& pred);

// numpy's median (GeoNet's kitti_eval): the mean of the two middle values for an even count
// (torch::median returns the lower one).
double numpy_median(const torch::Tensor& values);

struct EigenOptions {
  double min_depth = 1e-3, max_depth = 80;  // mask and clamp (Eigen et al. 2014 as in GeoNet's kitti_eval)
  bool garg_crop = true;                    // rows [0.408 H, 0.992 H), columns [0.036 W, 0.964 W)
  bool median_scaling = true;               // monocular: scale by median(gt)/median(pred), numpy's median
  double fixed_scale = 0;                   // > 0: scale by this instead (e.g. from the camera height)
};

// One image of the Eigen protocol: pred depth [h,w] (any size; resized bilinearly to the ground
// truth, as GeoNet does), gt [H,W] with 0 = no point. Returns the image's errors (pixels = 0 when
// nothing is valid), the scale applied through `scale` and median(gt)/median(pred) through
// `median_ratio` when given.
DepthErrors eigen_image_errors(const torch::Tensor& gt, const torch::Tensor& pred, const EigenOptions& options = {},
                               double* scale = nullptr, double* median_ratio = nullptr);

struct FlowErrors {
  double epe = 0;  // mean end-point error over valid pixels
  double fl = 0;   // fraction of valid pixels with EPE > 3 px and > 5% of |gt|
  int64_t pixels = 0;
};
// How a predicted flow is resized to the ground truth: nearest (GeoNet's flowlib, cv2 INTER_NEAREST:
// source pixel floor(x * w / W)) or bilinear.
enum class FlowResize { kNearest, kBilinear };

// Flow errors summed over pixels, for errors pooled over a set of pairs (KITTI's devkit pools
// Fl-bg / Fl-fg over all pixels of the dataset).
struct FlowErrorSums {
  double epe_sum = 0;
  int64_t outliers = 0;  // EPE > 3 px and > 5% of |gt|
  int64_t pixels = 0;
  FlowErrorSums& operator+=(const FlowErrorSums& other);
  double epe() const { return pixels ? epe_sum / static_cast<double>(pixels) : 0.0; }
  double fl() const { return pixels ? static_cast<double>(outliers) / static_cast<double>(pixels) : 0.0; }
};
// gt and pred [2,H,W] of the same size (see resize_flow), mask [H,W] (or [1,H,W]) boolean or {0,1}.
FlowErrorSums flow_error_sums(const torch::Tensor& gt, const torch::Tensor& mask, const torch::Tensor& pred);

// pred [2,h,w] (resized to the ground truth with u, v scaled), gt [2,H,W], valid [1,H,W] or [H,W].
FlowErrors flow_errors(const torch::Tensor& gt, const torch::Tensor& valid, const torch::Tensor& pred,
                       FlowResize resize = FlowResize::kNearest);

// Resizes a flow field to height x width, scaling u and v by the size ratios.
torch::Tensor resize_flow(const torch::Tensor& flow, int64_t height, int64_t width,
                          FlowResize resize = FlowResize::kNearest);

// The factor s minimising ||s pred - gt||^2: sum(gt.pred) / sum(pred.pred); `fallback` when pred is 0.
double least_squares_scale(const torch::Tensor& gt, const torch::Tensor& pred, double fallback = 1.0);

// SfMLearner's snippet ATE: the first positions aligned, one least-squares scale
// s = sum(gt.pred)/sum(pred.pred), ATE = sqrt(sum ||s pred - gt||^2) / N. gt, pred: [N,3].
double snippet_ate(const torch::Tensor& gt, const torch::Tensor& pred);

// Full-trajectory RMS position error after a similarity (Umeyama Sim(3)) alignment. [N,3] each.
double aligned_trajectory_rmse(const torch::Tensor& gt, const torch::Tensor& pred);

// KITTI odometry's own measures (the devkit's evaluate_odometry.cpp, as kitti-odom-eval computes
// them): from every `step`-th frame, for each length L, the first frame farther than L metres along
// the ground-truth path ends a segment; the relative motion's error E = (pred delta)^-1 (gt delta)
// gives t = |E.t| / L and r = acos(clamp((trace(E.R) - 1) / 2)) / L; both averaged over all
// segments. gt, pred: [N,4,4] camera-to-world poses at one scale (see align_trajectory_scale).
struct OdometryErrors {
  double t_err = 0;      // translational error, metres per metre (x 100: the devkit's %)
  double r_err = 0;      // rotational error, radians per metre (x 180/pi x 100: deg/100 m)
  int64_t segments = 0;  // 0 when the path is shorter than the shortest length (then t, r are 0)
};
inline const std::vector<double> kKittiSegmentLengths = {100, 200, 300, 400, 500, 600, 700, 800};
OdometryErrors kitti_odometry_errors(const torch::Tensor& gt, const torch::Tensor& pred,
                                     const std::vector<double>& lengths = kKittiSegmentLengths, int64_t step = 10);

// kitti-odom-eval's `--align scale`: both trajectories expressed in their first frame, the
// prediction's positions multiplied by s = sum(gt.pred) / sum(pred.pred) over all frames. Returns
// {gt, pred} so aligned, [N,4,4] float64.
std::pair<torch::Tensor, torch::Tensor> align_trajectory_scale(const torch::Tensor& gt, const torch::Tensor& pred);

// Whether camera-to-world poses [N,4,4] move at all: some position more than 1e-9 from the first.
// A trajectory without motion has nothing to align a scale to or score against.
bool trajectory_moves(const torch::Tensor& poses);

}  // namespace geo
