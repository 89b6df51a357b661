// The learning check: a short two-stage training on a tiny synthetic world must beat the untrained
// network and trivial baselines on held-out data: depth AbsRel (median-scaled, Eigen protocol on
// the held-out drive), pose ATE (5-frame snippets of an unseen sequence), and flow EPE (unseen
// pairs). If the photometric loss did not drive learning (e.g. replaced by zero), none of these
// would improve. Stage 2 (GeoNet's: the residual FlowNet alone on the frozen stage 1) must make the
// full flow beat the rigid flow of depth and pose on the moving cars, without worsening the static
// scene: with the residual zeroed the two are equal and the check fails. Depth scaled by the camera's
// height above the fitted road (no ground truth) must come close to median-scaled depth, and the
// motion in metres from it (geo_eval's metric trajectory, geo::Model::metric_relative_pose) close to
// the true motion.
#include "geo/geo.h"

#include "core/config.h"
#include "core/files.h"
#include "data/kitti/calib.h"
#include "data/image_io.h"
#include "data/synth/synth_writer.h"
#include "data/text_io.h"
#include "eval/protocols.h"
#include "train/trainer.h"

#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <cmath>
#include <map>

#include "eval_result.h"
#include "test_util.h"

namespace geo {
namespace {

using test::count_of;
using test::metric_of;

// One world and one two-stage training for the checks below (ctest runs them in one process: the
// e2e_tests executable is one ctest test), each check its own test so that a failure names it.
class Learning : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = test::fresh_dir("learning");
    world_ = SynthOptions::preset_named("tiny");
    world_.seed = 1;
    world_.flow_pairs = 10;
    world_.odometry_frames = 30;
    write_synth_world(root_ + "/world", world_);
    // bn_momentum 0.1 (LibTorch's): GeoNet's 0.001 averages BatchNorm's running statistics over
    // ~1000 batches, so after 300 iterations evaluation would still use near-initial statistics.
    const std::string yaml = R"(
model: {encoder_depth: 18, bn_momentum: 0.1, flow_zero_init: true}
data: {height: 64, width: 208, num_workers: 1, augment: {enabled: false}}
stages:
  - {name: stage1, iterations: 300, train: [depth, pose], batch_size: 4, learning_rate: 5.0e-4}
  - {name: stage2, iterations: 100, train: [flow], batch_size: 4, learning_rate: 2.0e-4,
     weights: {rigid: 0.0, disp_smooth: 0.0, flow: 1.0, flow_smooth: 0.2, flow_consistency: 0.2}}
logging: {interval: 50, summary_interval: 0, checkpoint_interval: 100, val_interval: 0, keep_last: 1}
run: {seed: 1, threads: 2}
)";
    config_ = parse_config(yaml, "learning.yaml", {"data.root=" + root_ + "/world/raw"});
    TrainOptions t;
    t.run_dir = run_ = root_ + "/run";
    trained_ok_ = train(config_, t) == 0;
  }
  void SetUp() override { ASSERT_TRUE(trained_ok_) << "the learning check's training failed"; }

  // A protocol on the world, of a model (null: the trivial baseline).
  static EvalResult eval(const std::string& split, Predictor* p, DepthScaling scaling = DepthScaling::kMedian) {
    EvalOptions e;
    e.split = split;
    e.data_root = root_ + "/world";
    e.scaling = scaling;
    return p ? evaluate(e, *p) : evaluate(e, *trivial_source());
  }

  // The trained run's results at the default (median) scaling: computed once, read by every test
  // that needs them (each evaluation is deterministic).
  static const EvalResult& trained_result(const std::string& split) {
    static std::map<std::string, EvalResult> done;
    auto it = done.find(split);
    if (it == done.end()) {
      Predictor trained(run_, "cpu");
      it = done.emplace(split, eval(split, &trained)).first;
    }
    return it->second;
  }

  static std::string root_, run_;
  static SynthOptions world_;
  static Config config_;
  static bool trained_ok_;
};
std::string Learning::root_, Learning::run_;
SynthOptions Learning::world_;
Config Learning::config_;
bool Learning::trained_ok_ = false;

TEST_F(Learning, ShortTrainingBeatsUntrainedAndTrivialBaselines) {
  Predictor untrained(config_, "cpu");
  struct Check {
    const char* split;
    const char* metric;
    double margin;  // trained must be below margin x the better baseline
  };
  for (const Check c :
       {Check{"eigen", "abs_rel", 0.92}, Check{"odometry", "ate_mean", 0.5}, Check{"kitti2015", "epe_all", 0.8}}) {
    const double tr = metric_of(trained_result(c.split), c.metric);
    const double un = metric_of(eval(c.split, &untrained), c.metric);
    const double tv = metric_of(eval(c.split, nullptr), c.metric);
    std::printf("learning check %-9s %-8s trained %.4f  untrained %.4f  trivial %.4f\n", c.split, c.metric, tr, un, tv);
    EXPECT_LT(tr, c.margin * std::min(un, tv)) << c.split << " " << c.metric;
  }
}

TEST_F(Learning, Int8KeepsTheAccuracyOfFp32) {
  // int8 (geo::Model::quantize_int8), calibrated on the first 8 frames of the first training drive,
  // against the same model in fp32 on the held-out data: AbsRel within 2% (relative), flow EPE within
  // 3%, ATE within 5%.
  std::vector<torch::Tensor> frames;
  for (int f = 0; f < 8; ++f)
    frames.push_back(
        read_image(root_ + "/world/raw/" + synth_drive_folder(1) + "/image_02/data/" + zero_padded(f, 10) + ".png"));
  Predictor int8(run_, "cpu");
  int8.quantize_int8(frames);
  struct Check {
    const char* split;
    const char* metric;
    double tolerance;
  };
  for (const Check c :
       {Check{"eigen", "abs_rel", 0.02}, Check{"kitti2015", "epe_all", 0.03}, Check{"odometry", "ate_mean", 0.05}}) {
    const double a = metric_of(trained_result(c.split), c.metric), b = metric_of(eval(c.split, &int8), c.metric);
    std::printf("learning check int8 %-9s %-8s fp32 %.4f  int8 %.4f (%+.2f%%)\n", c.split, c.metric, a, b,
                100 * (b / a - 1));
    EXPECT_LE(b, (1 + c.tolerance) * a) << c.split << " " << c.metric;
  }
}

TEST_F(Learning, ResidualFlowImprovesTheMovingCarsNotTheStaticScene) {
  // Stage 2: the residual flow against the rigid flow of the same model, on the moving cars (obj_map)
  // and on the static scene. Measured on this schedule (2026-11-27, LibTorch 1.13, checkpoints of
  // stage 2 after 100, 150 and 200 iterations): cars 3.39, 3.43, 3.43 px against 3.67 for the rigid
  // flow (0.925-0.935), static scene 1.59, 1.56, 1.56 against 1.65: 100 iterations give what 200 do.
  // The margin 0.97 leaves room for the noise of a short run while still requiring a gain that a
  // zero residual (ratio exactly 1) cannot give.
  const auto& flow = trained_result("kitti2015");
  const double fg = metric_of(flow, "epe_fg"), rigid_fg = metric_of(flow, "rigid_epe_fg");
  const double bg = metric_of(flow, "epe_bg"), rigid_bg = metric_of(flow, "rigid_epe_bg");
  std::printf("learning check stage 2: cars full %.4f rigid %.4f (%.3f), static full %.4f rigid %.4f (%.3f)\n", fg,
              rigid_fg, fg / rigid_fg, bg, rigid_bg, bg / rigid_bg);
  EXPECT_LT(fg, 0.97 * rigid_fg) << "the residual flow does not improve the moving cars";
  EXPECT_LE(bg, rigid_bg) << "the residual flow worsens the static scene";
}

TEST_F(Learning, CameraHeightScalesDepthWithoutGroundTruth) {
  Predictor trained(run_, "cpu");
  // Metric depth without ground truth: the scale from the camera's height above the road (geo_synth:
  // 1.65 m). On the demo's model (240 stage-1 iterations) AbsRel 0.237 against 0.217 median-scaled
  // and the factor 1.04 x the ground truth's; the bounds (20%, 0.8..1.25) leave room for a short
  // run's noise and still fail a broken fit (a fitted normal gave 0.43 x).
  const double median_abs_rel = metric_of(trained_result("eigen"), "abs_rel");
  const auto height = eval("eigen", &trained, DepthScaling::kCameraHeight);
  std::printf("learning check camera height: abs_rel %.4f (median scaling %.4f), scale agreement %.3f +- %.3f\n",
              metric_of(height, "abs_rel"), median_abs_rel, metric_of(height, "scale_agreement_median"),
              metric_of(height, "scale_agreement_std"));
  EXPECT_LT(metric_of(height, "abs_rel"), 1.2 * median_abs_rel);
  EXPECT_NEAR(metric_of(height, "scale_agreement_median"), 1.0, 0.25);
}

TEST_F(Learning, MotionInMetresWithoutGroundTruth) {
  Predictor trained(run_, "cpu");
  // Motion in metres without ground truth: the odometry sequence's trajectory with each step scaled
  // by its frame's road-plane factor. metric_scale_error is the factor a least-squares fit to the
  // true trajectory would still apply (1 = metres exactly). Measured here (seed 1, 300 stage-1
  // iterations): 1.16, and the library's unsmoothed steps 0.79 x the true lengths: the PoseNet's
  // translation of so short a run is not yet at its depth's scale. Bound: within a factor 1.5 of
  // metres (the network's own scale is arbitrary; see the printed unscaled ratio). The road plane is
  // found where the short run's near-field depth is flat enough (20% of the lower image within 5% of
  // one height): on a 2-core AVX2-only EPYC, whose kernels sum in another order, the same run finds
  // it in 12 of the 30 frames (2026-12-01; scale error 1.13). Bound: a third of the frames, which a
  // broken fit (none) or a depth without a road (a few) still fails.
  const auto odometry = eval("odometry", &trained, DepthScaling::kCameraHeight);
  std::printf("learning check metric trajectory: scale error %.3f, road plane in %lld of %lld frames\n",
              metric_of(odometry, "metric_scale_error"),
              static_cast<long long>(count_of(odometry, "frames_with_road_plane")),
              static_cast<long long>(count_of(odometry, "frames")));
  EXPECT_LT(std::abs(std::log(metric_of(odometry, "metric_scale_error"))), std::log(1.5));
  EXPECT_GE(3 * count_of(odometry, "frames_with_road_plane"), count_of(odometry, "frames"));

  // The library's metric step: relative_pose's rotation, its translation times metric_depth's factor
  // for the first frame, exactly; in metres, the true step lengths summed over the sequence within
  // the same bounds.
  const Model model = Model::load(run_);
  const std::string seq = root_ + "/world/odometry/sequences/09";
  const auto K = read_odometry_calib(seq + "/calib.txt").P[2].slice(1, 0, 3).clone();
  const auto truth = read_poses(root_ + "/world/odometry/poses/09.txt");
  auto frame = [&](int64_t f) { return read_image(seq + "/image_2/" + zero_padded(f, 6) + ".png"); };
  double predicted = 0, travelled = 0, unscaled = 0;
  int64_t steps = 0;
  for (int64_t f = 0; f + 1 < truth.size(0); f += 4) {
    const auto a = frame(f), b = frame(f + 1);
    std::vector<double> depth_scale, pose_scale;
    try {
      model.metric_depth(a, 1.65, K, &depth_scale);
    } catch (const Error&) {
      EXPECT_THROW(model.metric_relative_pose(a, b, 1.65, K), Error);  // the same missing road
      continue;
    }
    const auto step = model.metric_relative_pose(a, b, 1.65, K, &pose_scale);
    const auto plain = model.relative_pose(a, b, K);
    EXPECT_EQ(pose_scale, depth_scale);
    EXPECT_TRUE(torch::equal(step.slice(0, 0, 3).slice(1, 0, 3), plain.slice(0, 0, 3).slice(1, 0, 3)));
    EXPECT_TRUE(
        torch::allclose(step.slice(0, 0, 3).select(1, 3), plain.slice(0, 0, 3).select(1, 3) * depth_scale[0], 1e-6, 0));
    const auto true_step = torch::inverse(truth[f + 1]).matmul(truth[f]);  // points in f's camera -> f+1's
    predicted += step.slice(0, 0, 3).select(1, 3).norm().item<double>();
    unscaled += plain.slice(0, 0, 3).select(1, 3).norm().item<double>();
    travelled += true_step.slice(0, 0, 3).select(1, 3).norm().item<double>();
    ++steps;
  }
  std::printf("learning check metric steps: %lld steps, %.3f m predicted, %.3f m travelled (%.3f; unscaled %.3f)\n",
              static_cast<long long>(steps), predicted, travelled, predicted / travelled, unscaled / travelled);
  ASSERT_GT(steps, 3);
  EXPECT_LT(std::abs(std::log(predicted / travelled)), std::log(1.5));

  // The library's sequence: every frame's scale (Model::sequence_scales) finds the road in exactly
  // the frames geo_eval's metric trajectory found it in (the same depth, camera and fit), and the
  // chained trajectory (geo::chain_poses) travels the true length within the same bounds.
  std::vector<torch::Tensor> frames, motions;
  for (int64_t f = 0; f < truth.size(0); ++f) frames.push_back(frame(f));
  std::vector<size_t> without_road;
  auto scales = model.sequence_scales(frames, 1.65, K, &without_road);
  ASSERT_EQ(scales.size(), frames.size());
  EXPECT_EQ(static_cast<int64_t>(frames.size() - without_road.size()), count_of(odometry, "frames_with_road_plane"));
  for (size_t f = 0; f + 1 < frames.size(); ++f) motions.push_back(model.relative_pose(frames[f], frames[f + 1], K));
  scales.pop_back();
  const auto poses = chain_poses(motions, scales);
  const auto length = [](const torch::Tensor& p) {
    return (p.slice(0, 1).select(2, 3).slice(1, 0, 3) - p.slice(0, 0, -1).select(2, 3).slice(1, 0, 3))
        .norm(2, 1)
        .sum()
        .item<double>();
  };
  std::printf("learning check library trajectory: %.3f m against %.3f m travelled\n", length(poses), length(truth));
  EXPECT_LT(std::abs(std::log(length(poses) / length(truth))), std::log(1.5));
}

TEST_F(Learning, LearnedCameraConvergesAndKeepsDepth) {
  Predictor trained(run_, "cpu");
  const double median_abs_rel = metric_of(trained_result("eigen"), "abs_rel");
  const std::string seq = root_ + "/world/odometry/sequences/09";
  const auto truth = read_poses(root_ + "/world/odometry/poses/09.txt");
  auto frame = [&](int64_t f) { return read_image(seq + "/image_2/" + zero_padded(f, 6) + ".png"); };
  const auto& o = world_;
  // The learned camera (model.learn_intrinsics: the PoseNet's camera in every warp, the world's
  // calibration never used): after the same stage 1, its focal lengths within 10% of the world's
  // and its depth no worse than 1.15x the calibrated run's AbsRel. Measured 2026-11-25 (AMD EPYC,
  // 2 cores, the in-memory world of seed 1): fx 114.2, fy 111.2 against 120.8, 123.1 (from 144.2:
  // 0.69 W), AbsRel 0.2178 against 0.2108 (1.03x). A warp that ignores the learned camera leaves it
  // at its start (19% off); an unscaled head collapses to fx 44, fy 14.
  const std::string learned_yaml = R"(
model: {encoder_depth: 18, bn_momentum: 0.1, learn_intrinsics: true}
data: {height: 64, width: 208, num_workers: 1, augment: {enabled: false}}
stages:
  - {name: stage1, iterations: 300, train: [depth, pose], batch_size: 4, learning_rate: 5.0e-4}
logging: {interval: 50, summary_interval: 0, checkpoint_interval: 100, val_interval: 0, keep_last: 1}
run: {seed: 1, threads: 2}
)";
  TrainOptions lt;
  lt.run_dir = root_ + "/learned_camera";
  ASSERT_EQ(train(parse_config(learned_yaml, "learned.yaml", {"data.root=" + root_ + "/world/raw"}), lt), 0);
  Predictor learned(lt.run_dir, "cpu");
  const double learned_abs_rel = metric_of(eval("eigen", &learned), "abs_rel");
  const Model camera_model = Model::load(lt.run_dir);
  std::vector<torch::Tensor> cams;
  for (int64_t f = 0; f + 1 < truth.size(0); f += 3) cams.push_back(camera_model.intrinsics(frame(f), frame(f + 1)));
  const auto K_learned = torch::stack(cams).mean(0);
  const double fx = K_learned[0][0].item<double>(), fy = K_learned[1][1].item<double>();
  std::printf(
      "learning check learned camera: fx %.1f fy %.1f cx %.1f cy %.1f (truth %.1f %.1f %.1f %.1f), abs_rel %.4f "
      "(calibrated %.4f, %.3fx)\n",
      fx, fy, K_learned[0][2].item<double>(), K_learned[1][2].item<double>(), o.intrinsics.fx, o.intrinsics.fy,
      o.intrinsics.cx, o.intrinsics.cy, learned_abs_rel, median_abs_rel, learned_abs_rel / median_abs_rel);
  EXPECT_NEAR(fx, o.intrinsics.fx, 0.1 * o.intrinsics.fx);
  EXPECT_NEAR(fy, o.intrinsics.fy, 0.1 * o.intrinsics.fy);
  EXPECT_LT(learned_abs_rel, 1.15 * median_abs_rel);
}

}  // namespace
}  // namespace geo
