// The odometry protocol (eval/protocols.h): SfMLearner's 5-frame snippet ATE, KITTI's segment
// errors, the whole trajectory after a Sim(3) alignment, optionally in metres from the road plane.
#include "eval/protocol_parts.h"

#include "core/files.h"
#include "data/kitti/splits.h"
#include "data/text_io.h"
#include "eval/metrics.h"
#include "geometry/pose.h"

#include <spdlog/spdlog.h>

#include <filesystem>

namespace fs = std::filesystem;

namespace geo {
namespace {

torch::Tensor positions(const torch::Tensor& poses) { return poses.slice(1, 0, 3).select(2, 3); }  // [N,3]

}  // namespace

EvalResult eval_odometry(const EvalOptions& o, const std::string& root, PredictionSource& source) {
  const std::string seq = root + "/sequences/" + o.sequence, gt_path = root + "/poses/" + o.sequence + ".txt";
  require_file(gt_path, "ground-truth poses of sequence " + o.sequence);
  const auto gt = read_poses(gt_path);
  const int64_t n = gt.size(0);
  // Ground truth without motion: the whole sequence is refused; a static snippet (a stopped car)
  // scores ATE 0 whatever the prediction (the scale alignment scales it to nothing): counted, warned.
  if (!trajectory_moves(gt))
    throw std::runtime_error(gt_path +
                             ": the ground truth has no motion (every position is the first): a trajectory "
                             "error means nothing; nothing was scored");
  const bool metric = source.model() && o.scaling == DepthScaling::kCameraHeight;
  const TrajectoryAnswer answer =
      source.trajectory(SequenceQuery{seq, o.sequence, gt_path, n, metric ? camera_height_of(o, root) : 0.0});
  const torch::Tensor& traj = answer.trajectory;
  // 5-frame PoseNets (GeoNet's odometry model): snippet c-2..c+2 predicted at once, cam_to_world of
  // its frames in the target's frame (the target's pose is the identity).
  const auto& snippet_poses = answer.snippet_poses;
  const torch::Tensor& metric_traj = answer.metric;  // camera-height: the trajectory in metres, no ground truth used
  const int64_t frames_with_road = answer.frames_with_road;
  require_finite(traj, source.model() ? std::string("the predicted trajectory") : "the trajectory " + source.name());
  if (!o.output_poses.empty()) write_poses(o.output_poses, traj);
  std::vector<int64_t> centres;
  if (!o.split_file.empty()) {
    for (const auto& e : read_split(o.split_file)) centres.push_back(e.frame);
  } else {
    for (int64_t i = 0; i < n; ++i) centres.push_back(i);
  }
  int64_t static_snippets = 0;
  std::vector<double> ates;
  for (int64_t c : centres) {
    if (c < 2 || c + 2 >= n) continue;                       // snippets need two neighbours on each side
    auto rel = [&](const torch::Tensor& P, int64_t first) {  // positions in the snippet's first frame
      return positions(torch::inverse(P[first]).unsqueeze(0).matmul(P.slice(0, first, first + 5)));
    };
    // A 5-frame PoseNet is scored on its own snippet predictions (GeoNet's protocol); a 3-frame one
    // on the chained trajectory.
    const auto& own = snippet_poses[static_cast<size_t>(c)];
    if (rel(gt, c - 2).norm(2, 1).max().item<double>() < 1e-9) ++static_snippets;
    ates.push_back(snippet_ate(rel(gt, c - 2), own.defined() ? rel(own, 0) : rel(traj, c - 2)));
  }
  if (ates.empty()) throw std::runtime_error("sequence " + o.sequence + " has no 5-frame snippet");
  const auto t = torch::tensor(ates, torch::kFloat64);
  EvalResult r;
  r.metrics = {{"ate_mean", t.mean().item<double>()},
               {"ate_std", ates.size() > 1 ? t.std(false).item<double>() : 0.0},
               {"trajectory_rmse_sim3", aligned_trajectory_rmse(positions(gt), positions(traj))}};
  if (static_snippets > 0)
    spdlog::warn("{} of {} snippets have no ground-truth motion: they score ATE 0 whatever the prediction",
                 static_snippets, ates.size());
  // KITTI's own measures on the whole trajectory at the ground truth's scale (kitti-odom-eval's
  // --align scale: one least-squares factor, what a monocular trajectory needs).
  const auto [gt_aligned, traj_aligned] = align_trajectory_scale(gt, traj);
  const auto kitti = kitti_odometry_errors(gt_aligned, traj_aligned, o.segment_lengths);
  if (kitti.segments > 0) {
    r.metrics.emplace_back("t_err", kitti.t_err * 100);               // %
    r.metrics.emplace_back("r_err", kitti.r_err * 180 / M_PI * 100);  // deg / 100 m
  } else {
    spdlog::warn(
        "sequence {} is shorter than the shortest segment length ({} m): KITTI's t_err / r_err are not "
        "computed (geo_eval --segment-lengths)",
        o.sequence,
        o.segment_lengths.empty() ? 0.0 : *std::min_element(o.segment_lengths.begin(), o.segment_lengths.end()));
  }
  r.counts = {{"snippets", static_cast<int64_t>(ates.size())},
              {"frames", n},
              {"static_snippets", static_snippets},
              {"segments", kitti.segments}};
  if (metric_traj.defined()) {
    // Metres without ground truth: KITTI's measures on the trajectory as predicted (first frames
    // aligned, no scale fitted), and the factor the least-squares alignment would still apply.
    const auto g0 = torch::inverse(gt[0]).unsqueeze(0).matmul(gt.to(torch::kFloat64));
    const auto m0 = torch::inverse(metric_traj[0]).unsqueeze(0).matmul(metric_traj);
    const auto metric_kitti = kitti_odometry_errors(g0, m0, o.segment_lengths);
    if (metric_kitti.segments > 0) {
      r.metrics.emplace_back("metric_t_err", metric_kitti.t_err * 100);
      r.metrics.emplace_back("metric_r_err", metric_kitti.r_err * 180 / M_PI * 100);
    }
    r.metrics.emplace_back("metric_scale_error",
                           least_squares_scale(g0.slice(1, 0, 3).select(2, 3), m0.slice(1, 0, 3).select(2, 3), 0.0));
    r.counts.emplace_back("frames_with_road_plane", frames_with_road);
  }
  return r;
}

}  // namespace geo
