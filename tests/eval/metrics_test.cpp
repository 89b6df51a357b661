// Metrics against hand-computed values, and the protocols end to end on a synthetic world whose
// ground truth, given back as "predictions", must score perfectly.
#include "core/files.h"
#include "core/state_io.h"
#include "data/image_io.h"
#include "data/synth/synth_writer.h"
#include "data/text_io.h"
#include "eval/metrics.h"
#include "eval/protocols.h"
#include "pipeline/checkpoint.h"

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <tuple>

#include <spdlog/fmt/fmt.h>

#include "eval_result.h"
#include "synth_world.h"

namespace geo {
namespace {

TEST(DepthMetrics, HandComputed) {
  const auto gt = torch::tensor({2.0, 4.0}), pred = torch::tensor({1.0, 4.0});
  const auto e = depth_errors(gt, pred);
  EXPECT_NEAR(e.abs_rel, (0.5 + 0) / 2, 1e-12);     // |2-1|/2
  EXPECT_NEAR(e.sq_rel, (1.0 / 2 + 0) / 2, 1e-12);  // 1/2
  EXPECT_NEAR(e.rmse, std::sqrt(0.5), 1e-12);
  EXPECT_NEAR(e.rmse_log, std::sqrt(std::pow(std::log(2.0), 2) / 2), 1e-12);
  EXPECT_NEAR(e.a1, 0.5, 1e-12);  // ratio 2 fails 1.25, 1.5625 and 1.953
  EXPECT_NEAR(e.a2, 0.5, 1e-12);
  EXPECT_NEAR(e.a3, 0.5, 1e-12);
  EXPECT_NEAR(depth_errors(torch::tensor({1.9}), torch::tensor({1.0})).a3, 1.0, 1e-12);
}

TEST(DepthMetrics, EigenImageMedianScalingAndMask) {
  auto gt = torch::zeros({100, 100});
  gt.slice(0, 50, 90).slice(1, 10, 90).fill_(10.0);
  gt[60][20] = 90.0;                             // beyond 80 m: masked out
  gt[10][20] = 5.0;                              // above the Garg crop: masked out
  const auto pred = torch::full({50, 50}, 2.0);  // another size and scale
  double scale = 0;
  const auto e = eigen_image_errors(gt, pred, {}, &scale);
  EXPECT_NEAR(scale, 5.0, 1e-9);
  EXPECT_NEAR(e.abs_rel, 0.0, 1e-9);
  EXPECT_EQ(e.pixels, 40 * 80 - 1);
}

TEST(DepthMetrics, MedianScalingUsesNumpysMedian) {
  // numpy.median averages the two middle values of an even count; torch::median takes the lower.
  EXPECT_EQ(numpy_median(torch::tensor({4.0, 1.0, 3.0, 2.0})), 2.5);
  EXPECT_EQ(numpy_median(torch::tensor({5.0, 1.0, 3.0})), 3.0);
  // Four valid pixels (gt 1, 2, 3, 4; prediction 1 everywhere): scale 2.5, not 2.
  auto gt = torch::zeros({1, 4});
  gt[0][0] = 1.0, gt[0][1] = 2.0, gt[0][2] = 3.0, gt[0][3] = 4.0;
  EigenOptions o;
  o.garg_crop = false;
  double scale = 0;
  const auto e = eigen_image_errors(gt, torch::ones({1, 4}), o, &scale);
  EXPECT_EQ(scale, 2.5);
  EXPECT_NEAR(e.abs_rel, (1.5 / 1 + 0.5 / 2 + 0.5 / 3 + 1.5 / 4) / 4, 1e-12);
}

TEST(FlowMetrics, EpeAndFlOutliers) {
  auto gt = torch::zeros({2, 2, 2});
  gt[0].fill_(10.0);
  auto pred = gt.clone();
  pred[0][0][0] = 14.0;  // EPE 4 > 3 and > 0.5: outlier
  pred[1][0][1] = 1.0;   // EPE 1
  auto valid = torch::ones({1, 2, 2});
  valid[0][1][1] = 0;
  const auto e = flow_errors(gt, valid, pred);
  EXPECT_NEAR(e.epe, (4.0 + 1.0 + 0.0) / 3, 1e-9);
  EXPECT_NEAR(e.fl, 1.0 / 3, 1e-9);
  EXPECT_EQ(e.pixels, 3);
  // A half-size prediction is upsampled with its vectors doubled.
  const auto half = torch::full({2, 1, 1}, 5.0);
  EXPECT_NEAR(flow_errors(torch::full({2, 2, 2}, 10.0), torch::ones({2, 2}), half).epe, 0.0, 1e-9);
}

TEST(FlowMetrics, SumsPoolOverMasksAndPairs) {
  // The devkit's Fl-bg / Fl-fg: errors pooled over the pixels of every pair, not averaged per pair.
  auto gt = torch::zeros({2, 2, 2});
  gt[0].fill_(10.0);
  auto pred = gt.clone();
  pred[0][0][0] = 14.0;                                                    // EPE 4, outlier
  pred[1][0][1] = 1.0;                                                     // EPE 1
  const auto fg = torch::tensor({true, true, false, false}).view({2, 2});  // the top row
  auto a = flow_error_sums(gt, fg, pred);
  EXPECT_EQ(a.pixels, 2);
  EXPECT_EQ(a.outliers, 1);
  EXPECT_NEAR(a.epe(), 2.5, 1e-12);
  const auto bg = flow_error_sums(gt, ~fg, pred);
  EXPECT_EQ(bg.pixels, 2);
  EXPECT_EQ(bg.epe(), 0.0);
  a += flow_error_sums(gt, torch::tensor({true, false, false, false}).view({1, 2, 2}), pred);  // a second pair
  EXPECT_EQ(a.pixels, 3);
  EXPECT_NEAR(a.epe(), 9.0 / 3, 1e-12);  // (4 + 1 + 4) / 3, where per-pair means would give (2.5 + 4) / 2
  EXPECT_NEAR(a.fl(), 2.0 / 3, 1e-12);
  EXPECT_EQ(flow_error_sums(gt, torch::zeros({2, 2}), pred).epe(), 0.0);  // no pixel: 0, pixels 0
}

TEST(FlowMetrics, ResizeNearestAsGeoNetsFlowlibOrBilinear) {
  // u = 0, 4 on a 1x2 prediction, resized to 1x4 (u doubled): nearest (cv2 INTER_NEAREST, source
  // floor(x / 2)) gives 0 0 8 8; bilinear (half-pixel centres) gives 0 2 6 8.
  auto flow = torch::zeros({2, 1, 2});
  flow[0][0][1] = 4.0;
  const auto n = resize_flow(flow, 1, 4, FlowResize::kNearest);
  const auto b = resize_flow(flow, 1, 4, FlowResize::kBilinear);
  EXPECT_TRUE(torch::equal(n[0][0], torch::tensor({0.f, 0.f, 8.f, 8.f}))) << n;
  EXPECT_TRUE(torch::allclose(b[0][0], torch::tensor({0.f, 2.f, 6.f, 8.f}))) << b;
  EXPECT_EQ(n[1].abs().sum().item<float>(), 0.f);
}

TEST(PoseMetrics, SnippetAteIsScaleAndOffsetInvariantAndHandComputed) {
  const auto gt =
      torch::tensor({0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 3.0, 0.0, 0.0, 4.0}).view({5, 3});
  EXPECT_NEAR(snippet_ate(gt, gt * 0.5 + 3.0), 0.0, 1e-12);
  // Zero motion: scale has no effect (0/0 -> 1), error = sqrt(0+1+4+9+16)/5.
  EXPECT_NEAR(snippet_ate(gt, torch::zeros({5, 3})), std::sqrt(30.0) / 5, 1e-12);
  // Similarity alignment of a rotated, scaled, shifted trajectory is exact.
  const auto traj = torch::rand({20, 3}, torch::kFloat64);
  const auto R = torch::tensor({0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0}, torch::kFloat64).view({3, 3});
  EXPECT_NEAR(aligned_trajectory_rmse(traj, 2.5 * traj.matmul(R.t()) + 1.0), 0.0, 1e-9);
}

using test::count_of;
using test::metric_of;

// KITTI odometry's t_err / r_err (devkit, kitti-odom-eval) on a hand-made pair: 21 frames 1 m apart
// along z, segment lengths 5 and 10 m, every 10th frame: segments (0 -> 6), (0 -> 11), (10 -> 16)
// (the first frame farther than L along the path; 10 + 10 has no frame 21).
TEST(PoseMetrics, KittiOdometryErrorsAsTheDevkitOnAHandMadePair) {
  auto pose = [](double z, double yaw) {
    auto T = torch::eye(4, torch::kFloat64);
    T[0][0] = std::cos(yaw), T[0][2] = std::sin(yaw), T[2][0] = -std::sin(yaw), T[2][2] = std::cos(yaw);
    T[2][3] = z;
    return T;
  };
  std::vector<torch::Tensor> gt, longer, turning;
  for (int i = 0; i < 21; ++i) {
    gt.push_back(pose(i, 0));
    longer.push_back(pose(1.1 * i, 0));    // 10% too fast: the error is 0.1 x the segment's frames
    turning.push_back(pose(i, 0.01 * i));  // right positions, heading off by 0.01 rad per frame
  }
  const std::vector<double> lengths = {5, 10};
  const auto a = kitti_odometry_errors(torch::stack(gt), torch::stack(longer), lengths);
  EXPECT_EQ(a.segments, 3);
  EXPECT_NEAR(a.t_err, (0.6 / 5 + 1.1 / 10 + 0.6 / 5) / 3, 1e-12);
  EXPECT_NEAR(a.r_err, 0.0, 1e-12);
  // Rotation: E = (R_f^T R_l, R_f^T (t_l - t_f))^-1 (I, t_l - t_f): angle 0.01 (l - f); translation
  // |t - R_y(-0.01 f) t| = 2 |t| sin(0.005 f), nonzero only for the segment from frame 10.
  const auto b = kitti_odometry_errors(torch::stack(gt), torch::stack(turning), lengths);
  EXPECT_EQ(b.segments, 3);
  EXPECT_NEAR(b.r_err, (0.06 / 5 + 0.11 / 10 + 0.06 / 5) / 3, 1e-12);
  EXPECT_NEAR(b.t_err, (0.0 + 0.0 + 2 * 6 * std::sin(0.05) / 5) / 3, 1e-12);
  EXPECT_EQ(kitti_odometry_errors(torch::stack(gt), torch::stack(gt), lengths).t_err, 0.0);
  EXPECT_EQ(kitti_odometry_errors(torch::stack(gt), torch::stack(gt)).segments, 0);  // 20 m < 100 m
  // kitti-odom-eval's --align scale: the 10% too long trajectory scaled back is the truth.
  const auto [g, p] = align_trajectory_scale(torch::stack(gt), torch::stack(longer));
  EXPECT_TRUE(torch::allclose(p, g, 0, 1e-12));
  EXPECT_NEAR(kitti_odometry_errors(g, p, lengths).t_err, 0.0, 1e-12);
}

// A small synthetic world of its own for each protocol test (6 frames per drive, 2 flow pairs, 8
// odometry frames), in <name>/world; `traffic`: stop-and-go traffic.
std::string protocol_world(const std::string& name, bool traffic = false) {
  const auto root = test::fresh_dir(name);
  std::filesystem::rename(test::write_small_world(name + "_world", 6, 2, 8, traffic), root + "/world");
  return root;
}

// The options of `split` on <root>/world.
EvalOptions options_for(const std::string& split, const std::string& root) {
  EvalOptions o;
  o.split = split;
  o.data_root = root + "/world";
  return o;
}

// The protocol's score of prediction files.
EvalResult score_files(const EvalOptions& o, const std::string& predictions) {
  return evaluate(o, *file_source(predictions));
}

// The Eigen test list's dense ground truth as predictions (named by line of the list).
std::vector<std::string> dense_truth_as_predictions(const std::string& root) {
  const auto tests = read_lines(root + "/world/raw/splits/eigen/test_files.txt");
  std::filesystem::create_directories(root + "/depth");
  for (size_t i = 0; i < tests.size(); ++i) {
    const auto d = tests[i].substr(0, tests[i].find("/image_02"));
    const auto f = tests[i].substr(tests[i].rfind('/') + 1);
    std::filesystem::copy_file(root + "/world/raw/" + d + "/proj_depth/groundtruth/image_02/" + f,
                               root + "/depth/" + zero_padded(static_cast<long long>(i), 6) + ".png");
  }
  return tests;
}

TEST(Protocols, EigenDepthOfTheTruthScoresNearlyPerfectly) {
  const auto root = protocol_world("protocols_eigen");
  const auto tests = dense_truth_as_predictions(root);
  EvalOptions e = options_for("eigen", root);
  const std::string predictions = root + "/depth";
  const auto depth = score_files(e, predictions);
  EXPECT_EQ(depth.counts[0].second, static_cast<int64_t>(tests.size()));
  // The protocol's ground truth is the Velodyne x (27 cm behind the camera here, as in KITTI) at
  // round(x/z) - 1, so even the dense camera-z truth scores near, not exactly, zero.
  EXPECT_LT(depth.metrics[0].second, 0.1) << "abs_rel of the truth";
  EXPECT_GT(depth.metrics[4].second, 0.95);
  e.matlab_offset = false;
  const double exact = score_files(e, predictions).metrics[0].second;
  EXPECT_LT(exact, depth.metrics[0].second);
  std::printf("abs_rel of the dense truth: %.4f (reference pixel shift), %.4f (exact pixels)\n",
              depth.metrics[0].second, exact);
  EXPECT_EQ(count_of(depth, "velodyne_points_non_finite"), 0);
  EXPECT_EQ(count_of(depth, "predictions_resized"), 0);
  {  // A prediction file of another size is resized and counted; one with H and W swapped is refused.
    const std::string first = predictions + "/000000.png";
    const auto truth = read_depth_png(first);  // [1,H,W]
    const int64_t H = truth.size(1), W = truth.size(2);
    write_depth_png(first, torch::full({1, H / 2, W / 2}, 10.0f));
    EXPECT_EQ(count_of(score_files(e, predictions), "predictions_resized"), 1);
    write_depth_png(first, torch::full({1, W, H}, 10.0f));
    GEO_EXPECT_THROW_WITH(score_files(e, predictions), "line 1", std::to_string(W) + "x" + std::to_string(H) + " (HxW)",
                          "(H and W swapped)");
    write_depth_png(first, truth);
  }
  // NaN points in a scan are left out of the ground truth and counted; the metrics do not move.
  {
    const auto d = tests[0].substr(0, tests[0].find("/image_02"));
    const auto f = tests[0].substr(tests[0].rfind('/') + 1);
    const std::string velo = root + "/world/raw/" + d + "/velodyne_points/data/" + f.substr(0, f.size() - 4) + ".bin";
    const auto points = read_velodyne(velo);
    auto nan_point = torch::full({2, 4}, std::nanf(""));
    write_velodyne(velo, torch::cat({points, nan_point}));
    const auto with_nan = score_files(e, predictions);
    EXPECT_EQ(count_of(with_nan, "velodyne_points_non_finite"), 2);
    EXPECT_EQ(with_nan.metrics[0].second, exact);
    write_velodyne(velo, points);
  }
  // --export-gt: the ground truth the protocol scores against, written without a model, no metrics;
  // scored as predictions it matches itself to the PNG's 1/256 m (median ratio 1, every pixel within
  // delta < 1.25), with either pixel convention.
  for (const bool offset : {true, false}) {
    EvalOptions g = options_for("eigen", root);
    g.matlab_offset = offset;
    const std::string dir = root + (offset ? "/gt_offset" : "/gt_exact");
    const auto exported = export_eigen_ground_truth(g, dir);
    EXPECT_TRUE(exported.metrics.empty());
    EXPECT_EQ(exported.counts[0], (std::pair<std::string, int64_t>{"exported", static_cast<int64_t>(tests.size())}));
    const auto itself = score_files(g, dir);
    EXPECT_LT(metric_of(itself, "abs_rel"), 1e-3) << "offset " << offset;
    EXPECT_EQ(metric_of(itself, "a1"), 1.0);
    EXPECT_NEAR(metric_of(itself, "scale_ratio_median"), 1.0, 1e-3);
  }
  EXPECT_NE(test::read_file(root + "/gt_offset/000000.png"), test::read_file(root + "/gt_exact/000000.png"));
}

// In traffic the car ahead that keeps its distance (raw/<drive>/obj_map/with_camera.txt) is scored
// on its own as well: the dense truth in metres scores it near 0 and as deep as the static scene
// says (depth ratio 1); the same predictions with that car twice as far score it near 1, every one
// of its pixels outside delta < 1.25, at twice the ratio, and move the moving objects' pooled error
// by exactly what they add (no other pixel changed).
TEST(Protocols, EigenScoresTheCarsThatKeepTheirDistanceApart) {
  const auto root = protocol_world("protocols_with_camera", true);
  const auto tests = dense_truth_as_predictions(root);
  EvalOptions e = options_for("eigen", root);
  e.scaling = DepthScaling::kNone;
  e.matlab_offset = false;
  const auto truth = score_files(e, root + "/depth");
  const int64_t pixels = count_of(truth, "with_camera_pixels");
  EXPECT_GT(pixels, 50);
  EXPECT_LT(pixels, count_of(truth, "moving_pixels"));
  EXPECT_LT(metric_of(truth, "with_camera_abs_rel"), 0.05);
  EXPECT_NEAR(metric_of(truth, "with_camera_depth_ratio"), 1.0, 0.05);
  for (size_t i = 0; i < tests.size(); ++i) {
    const auto drive = tests[i].substr(0, tests[i].find("/image_02"));
    const auto frame = tests[i].substr(tests[i].rfind('/') + 1);
    const auto values = read_lines(root + "/world/raw/" + drive + "/obj_map/with_camera.txt");
    ASSERT_EQ(values.size(), 1u);
    const auto map = read_object_map(root + "/world/raw/" + drive + "/obj_map/image_02/" + frame);
    const std::string file = root + "/depth/" + zero_padded(static_cast<long long>(i), 6) + ".png";
    auto depth = read_depth_png(file);
    depth = torch::where(map == std::stoi(values[0]), 2 * depth, depth);
    write_depth_png(file, depth);
  }
  const auto doubled = score_files(e, root + "/depth");
  EXPECT_EQ(count_of(doubled, "with_camera_pixels"), pixels);
  EXPECT_NEAR(metric_of(doubled, "with_camera_abs_rel"), 1.0, 0.1);
  EXPECT_EQ(metric_of(doubled, "with_camera_a1"), 0.0);
  // Against the static scene the car is twice as deep as the truth's, exactly (a ratio of medians).
  EXPECT_DOUBLE_EQ(metric_of(doubled, "with_camera_depth_ratio"), 2 * metric_of(truth, "with_camera_depth_ratio"));
  const auto pooled = [](const EvalResult& r, const std::string& name) {
    return metric_of(r, name + "_abs_rel") * static_cast<double>(count_of(r, name + "_pixels"));
  };
  EXPECT_NEAR(pooled(doubled, "moving") - pooled(truth, "moving"),
              pooled(doubled, "with_camera") - pooled(truth, "with_camera"), 1e-6 * static_cast<double>(pixels));
  // A list that names no object-map value is refused naming the file; without lists no such rows.
  const auto drive = tests[0].substr(0, tests[0].find("/image_02"));
  const std::string list = root + "/world/raw/" + drive + "/obj_map/with_camera.txt";
  test::write_text(list, "1.5\n");
  GEO_EXPECT_THROW_WITH(score_files(e, root + "/depth"), list, "'1.5' is not an object-map value");
  std::filesystem::remove(list);
  const auto without = score_files(e, root + "/depth");
  for (const auto& m : without.metrics) EXPECT_NE(m.first.rfind("with_camera", 0), 0u) << m.first;
  EXPECT_EQ(metric_of(without, "moving_abs_rel"), metric_of(doubled, "moving_abs_rel"));
}

TEST(Protocols, Kitti2015FlowOfTheTruthScoresPerfectly) {
  const auto root = protocol_world("protocols_flow");
  EvalOptions f = options_for("kitti2015", root);
  std::string predictions = root + "/world/kitti2015/training/flow_occ";
  const auto flow = score_files(f, predictions);
  EXPECT_NEAR(flow.metrics[0].second, 0.0, 1e-9);
  EXPECT_EQ(flow.counts[0].second, 2);
  // geo_synth's object maps: background and foreground scored apart, pixels counted (the flow_occ
  // pixels split between them), no rigid_ rows without a model.
  EXPECT_EQ(count_of(flow, "pairs_with_object_map"), 2);
  EXPECT_EQ(count_of(flow, "pixels_bg") + count_of(flow, "pixels_fg"), count_of(flow, "pixels_all"));
  EXPECT_NEAR(metric_of(flow, "epe_bg"), 0.0, 1e-9);
  for (const auto& m : flow.metrics) EXPECT_NE(m.first.rfind("rigid_", 0), 0u) << m.first;
  {  // an object map is the moving cars of its frame: a car's pixels in flow_occ, off the ground
    const auto objects = read_object_map(root + "/world/kitti2015/training/obj_map/000000_10.png");
    EXPECT_EQ(objects.sizes(), (torch::IntArrayRef{64, 208}));
    EXPECT_EQ(objects.scalar_type(), torch::kUInt8);
  }
  EXPECT_EQ(count_of(flow, "predictions_resized"), 0);
  {  // A prediction of another size than its ground truth is resized and counted, not silently.
    const std::string small = root + "/flow_small";
    std::filesystem::copy(predictions, small);
    const auto first = std::filesystem::directory_iterator(small)->path().string();
    write_flow_png(first, torch::zeros({2, 4, 6}), torch::ones({1, 4, 6}));
    EXPECT_EQ(count_of(score_files(f, small), "predictions_resized"), 1);
    // A prediction with every valid bit 0 holds no flow: refused, not scored as zero flow.
    write_flow_png(first, torch::ones({2, 4, 6}), torch::zeros({1, 4, 6}));
    GEO_EXPECT_THROW_WITH(score_files(f, small), first, "no pixel of the flow prediction is marked valid");
  }
  test::write_text(root + "/pairs.txt", "training/image_2/000001_10.png\n");
  f.split_file = root + "/pairs.txt";
  EXPECT_EQ(score_files(f, predictions).counts[0].second, 1);
  test::write_text(root + "/pairs.txt", "training/image_2/000007_10.png\n");
  GEO_EXPECT_THROW_WITH(score_files(f, predictions), "000007");
  // Ground truth that cannot score: an all-invalid flow map is left out and counted (it used to
  // count as EPE 0).
  f.split_file.clear();
  const std::string occ1 = root + "/world/kitti2015/training/flow_occ/000001_10.png";
  const auto gt1 = read_flow_png(occ1);
  write_flow_png(occ1, gt1.flow, torch::zeros_like(gt1.valid));
  const auto partial = score_files(f, root + "/world/kitti2015/training/flow_noc");
  EXPECT_EQ(partial.counts[0], (std::pair<std::string, int64_t>{"pairs", 1}));
  EXPECT_EQ(count_of(partial, "pairs_without_ground_truth"), 1);
}

TEST(Protocols, OdometryTrajectoryOfTheTruthScoresPerfectly) {
  const auto root = protocol_world("protocols_pose");
  EvalOptions p = options_for("odometry", root);
  const auto pose = score_files(p, root + "/world/odometry/poses/09.txt");
  EXPECT_NEAR(pose.metrics[0].second, 0.0, 1e-6);
  EXPECT_EQ(pose.counts[0].second, 4);  // centres 2..5 of 8 frames
  write_poses(root + "/still.txt", torch::eye(4, torch::kFloat64).repeat({8, 1, 1}));
  EXPECT_GT(score_files(p, root + "/still.txt").metrics[0].second, 0.5);
  // A trajectory with a NaN is an error, not a nan metric with exit code 0.
  auto nan_traj = read_poses(root + "/world/odometry/poses/09.txt");
  nan_traj[3][0][3] = std::nan("");
  write_poses(root + "/nan.txt", nan_traj);
  GEO_EXPECT_THROW_WITH(score_files(p, root + "/nan.txt"), "nan.txt line 4", "NaN or infinity");
  // Non-finite metrics are written as JSON null and read back as NaN.
  EvalResult with_nan = pose;
  with_nan.metrics[1].second = std::nan("");
  EXPECT_NE(with_nan.json().find("\"ate_std\": null"), std::string::npos) << with_nan.json();
  test::write_text(root + "/nan.json", with_nan.json());
  EXPECT_TRUE(std::isnan(read_result(root + "/nan.json").metrics[1].second));
  // Results survive a JSON round trip.
  test::write_text(root + "/r.json", pose.json());
  const auto back = read_result(root + "/r.json");
  EXPECT_EQ(back.split, "odometry");
  EXPECT_NEAR(back.metrics[0].second, pose.metrics[0].second, 1e-9);
  EXPECT_EQ(back.data_root, pose.data_root);
  EXPECT_EQ(back.subset, "sequence 09");
}

// --compare prints what each column scored and a note for every difference other than the model;
// a file that is not a results file is refused by name.
TEST(Protocols, ComparisonsSayHowTheColumnsDiffer) {
  EvalResult a;
  a.split = "eigen";
  a.data_root = "/data/a";
  a.scaling = "median";
  a.metrics = {{"abs_rel", 0.25}};
  a.counts = {{"images", 40}, {"pixels", 1000}};
  EvalResult b = a;
  b.metrics = {{"abs_rel", 0.2}};
  const auto alike = format_results({a, b}, {"a", "b"});
  EXPECT_EQ(alike.find("note:"), std::string::npos) << alike;
  EXPECT_NE(alike.find(fmt::format("{:<22} {:>14} {:>14}\n", "scored", "40 images", "40 images")), std::string::npos)
      << alike;
  b.scaling = "camera-height 1.650000 m";
  b.counts = {{"images", 23}, {"pixels", 1000}};
  b.data_root = "/data/b";
  b.training_drives_unknown = "no training config";
  const auto unlike = format_results({a, b}, {"a", "b"});
  EXPECT_NE(unlike.find("note: the columns differ in scaling: a median, b camera-height 1.650000 m\n"),
            std::string::npos)
      << unlike;
  EXPECT_NE(unlike.find("note: the columns differ in data root: a /data/a, b /data/b\n"), std::string::npos);
  EXPECT_NE(unlike.find("note: the columns differ in 'images' (the metrics average over different sets): a 40, b 23\n"),
            std::string::npos);
  EXPECT_EQ(unlike.find("differ in 'pixels'"), std::string::npos);
  EXPECT_NE(unlike.find("whether it trained on test drives is unknown: no training config"), std::string::npos);
  // One model in fp32 and in int8: the precision is recorded in the results file and noted.
  EvalResult fp32 = a, int8 = a;
  fp32.precision = "fp32";
  int8.precision = "int8";
  const std::string root = test::fresh_dir("compare_files");
  test::write_text(root + "/int8.json", int8.json());
  EXPECT_EQ(read_result(root + "/int8.json").precision, "int8");
  const auto precisions = format_results({fp32, read_result(root + "/int8.json")}, {"fp32", "int8"});
  EXPECT_NE(precisions.find("note: the columns differ in precision: fp32 fp32, int8 int8\n"), std::string::npos)
      << precisions;
  // Names longer than a column are shown whole, the columns widened to them.
  const auto long_names = format_results({a, a}, {"automask1200-42", "a"});
  EXPECT_NE(long_names.find(fmt::format("{:<22} {:>15} {:>15}\n", "metric", "automask1200-42", "a")), std::string::npos)
      << long_names;
  EXPECT_NE(long_names.find(fmt::format("{:<22} {:>15} {:>15}\n", "abs_rel", "0.2500", "0.2500")), std::string::npos)
      << long_names;
  for (const auto& [name, text, why] : std::vector<std::tuple<std::string, std::string, std::string>>{
           {"list.json", "[1, 2]", "not a JSON object"},
           {"config.json", "{\"model\": {\"use_fr\": true}}", "no 'split'"},
           {"other.json", "{\"split\": \"cityscapes\", \"metrics\": {\"x\": 1}, \"counts\": {\"n\": 1}}",
            "unknown split 'cityscapes'"},
           {"empty.json", "{\"split\": \"eigen\", \"metrics\": {}, \"counts\": {}}", "no metrics or no counts"},
           {"scalar.json", "{\"split\": \"eigen\", \"metrics\": 3, \"counts\": {\"n\": 1}}", "must be objects"}}) {
    test::write_text(root + "/" + name, text);
    GEO_EXPECT_THROW_WITH(read_result(root + "/" + name), root + "/" + name + "' is not a geo_eval results file", why);
  }
}

// Untrained models: a 5-frame PoseNet is evaluated on odometry snippets (GeoNet's protocol), a
// KITTI 2015 pair with its previous frame (_09) feeds the PoseNet (09, 10, 11), a FlowNet's rigid
// flow is scored beside its full flow, and images that outnumber the poses are an error.
TEST(Protocols, ModelsOnTheOdometryAndFlowProtocols) {
  const auto root = protocol_world("protocols_models");
  const EvalOptions p = options_for("odometry", root);
  Config c5 = parse_config("model: {encoder_depth: 18}\ndata: {height: 64, width: 208, seq_length: 5}\n");
  Predictor five(c5, "cpu");
  const auto r5 = evaluate(p, five);
  EXPECT_EQ(r5.counts[0].second, 4);
  EXPECT_TRUE(std::isfinite(r5.metrics[0].second));
  Config c3 = parse_config("model: {encoder_depth: 18}\ndata: {height: 64, width: 208}\n");
  Predictor three(c3, "cpu");
  std::filesystem::remove(root + "/world/kitti2015/training/image_2/000000_09.png");  // geo_synth writes both
  const auto r3 = evaluate(options_for("kitti2015", root), three);
  EXPECT_EQ(r3.counts.back(), (std::pair<std::string, int64_t>{"pairs_with_frame_09", 1}));
  EXPECT_TRUE(std::isfinite(metric_of(r3, "rigid_epe_all")));
  EXPECT_NE(metric_of(r3, "rigid_epe_all"), metric_of(r3, "epe_all"));
  EXPECT_TRUE(std::isfinite(metric_of(r3, "rigid_epe_bg")));
  const std::string images = root + "/world/odometry/sequences/09/image_2/";
  {  // The streamed trajectory (the protocol holds the frames of one snippet) is the chain of the
     // PoseNet's steps over snippets (j-1, j, j+1), clamped at the ends, computed here from all frames.
    EvalOptions q = options_for("odometry", root);
    q.output_poses = root + "/streamed.txt";
    evaluate(q, three);
    const auto streamed = read_poses(q.output_poses);
    ASSERT_EQ(streamed.size(0), 8);
    std::vector<torch::Tensor> frames;
    for (int64_t f = 0; f < 8; ++f)
      frames.push_back(read_image_resized(images + zero_padded(f, 6) + ".png", 64, 208).unsqueeze(0));
    auto chained = torch::eye(4, torch::kFloat64);
    EXPECT_TRUE(torch::allclose(streamed[0], chained));
    for (int64_t j = 0; j + 1 < 8; ++j) {
      const auto next_from_j = three.pose(frames[j], {frames[std::max<int64_t>(j - 1, 0)], frames[j + 1]})[0][1];
      chained = chained.matmul(torch::inverse(next_from_j.cpu().to(torch::kFloat64)));
      EXPECT_TRUE(torch::allclose(streamed[j + 1], chained, 1e-5, 1e-6)) << "frame " << j + 1;
    }
  }
  std::filesystem::copy_file(images + "000007.png", images + "000008.png");
  GEO_EXPECT_THROW_WITH(evaluate(p, three), "09.txt holds 8 poses", "000008.png exists");
}

// Predictions and ground truth that cannot be right are refused (naming the file) or, where a
// protocol has an answer, scored and counted in the results: depths <= 0, ground truth without
// motion, frames or flow maps of another size than their pair.
TEST(Protocols, PredictionsAndGroundTruthThatCannotBeRightAreRefusedOrCounted) {
  const auto root = test::fresh_dir("protocols_bad");
  std::filesystem::rename(test::write_small_world("protocols_bad_world", 8, 1, 9), root + "/world");
  const auto tests = read_lines(root + "/world/raw/splits/eigen/test_files.txt");
  ASSERT_GE(tests.size(), 2u);
  EvalOptions e;
  e.split = "eigen";
  e.data_root = root + "/world";
  const std::string depth_dir = root + "/depth";
  auto depth_file = [&](size_t i) { return root + "/depth/" + zero_padded(static_cast<long long>(i), 6) + ".png"; };
  std::filesystem::create_directories(root + "/depth");
  for (size_t i = 0; i < tests.size(); ++i) write_depth_png(depth_file(i), torch::full({1, 64, 208}, 10.0));
  EXPECT_EQ(count_of(score_files(e, depth_dir), "predictions_with_nonpositive_depth"), 0);
  auto half = torch::full({1, 64, 208}, 10.0);
  half.slice(2, 0, 104).zero_();  // 0 in a depth PNG: no depth
  write_depth_png(depth_file(1), half);
  EXPECT_EQ(count_of(score_files(e, depth_dir), "predictions_with_nonpositive_depth"), 1);
  write_depth_png(depth_file(1), torch::zeros({1, 64, 208}));
  GEO_EXPECT_THROW_WITH(score_files(e, depth_dir), "line 2", "is <= 0 everywhere", "nothing was scored");

  // Odometry: no motion at all is refused; a stopped car's snippet scores 0 whatever the prediction,
  // so it is counted.
  EvalOptions p;
  p.split = "odometry";
  p.data_root = root + "/world";
  const std::string gt_path = root + "/world/odometry/poses/09.txt";
  const auto moving = read_poses(gt_path);
  ASSERT_EQ(moving.size(0), 9);
  EXPECT_EQ(count_of(score_files(p, gt_path), "static_snippets"), 0);
  auto stopped = moving.clone();
  for (int64_t i = 1; i < 5; ++i) stopped[i] = moving[0];  // frames 0-4 at one place: snippet 2
  write_poses(gt_path, stopped);
  EXPECT_EQ(count_of(score_files(p, gt_path), "static_snippets"), 1);
  write_poses(gt_path, moving[0].unsqueeze(0).repeat({9, 1, 1}));
  GEO_EXPECT_THROW_WITH(score_files(p, gt_path), gt_path, "has no motion");
  write_poses(gt_path, moving);
  // KITTI's t_err / r_err: none on a path shorter than 100 m, 0 for the truth itself on short segments.
  EXPECT_EQ(count_of(score_files(p, gt_path), "segments"), 0);
  p.segment_lengths = {0.1};
  const auto short_segments = score_files(p, gt_path);
  EXPECT_GT(count_of(short_segments, "segments"), 0);
  EXPECT_NEAR(metric_of(short_segments, "t_err"), 0.0, 1e-6);
  EXPECT_NEAR(metric_of(short_segments, "r_err"), 0.0, 1e-2);  // acos near 1: ~1e-8 rad of rounding

  // Flow: flow_noc of another size than flow_occ; a pair's second frame of another size (a model
  // reads the frames).
  EvalOptions f;
  f.split = "kitti2015";
  f.data_root = root + "/world";
  const std::string occ_dir = root + "/world/kitti2015/training/flow_occ";
  const std::string noc = root + "/world/kitti2015/training/flow_noc/000000_10.png";
  const auto noc_gt = read_flow_png(noc);
  write_flow_png(noc, torch::zeros({2, 32, 104}), torch::ones({1, 32, 104}));
  GEO_EXPECT_THROW_WITH(score_files(f, occ_dir), noc, "is 104x32", "flow_occ/000000_10.png is 208x64");
  write_flow_png(noc, noc_gt.flow, noc_gt.valid);
  const std::string second = root + "/world/kitti2015/training/image_2/000000_11.png";
  write_image(second, torch::zeros({3, 32, 104}));
  Predictor untrained(parse_config("model: {encoder_depth: 18}\ndata: {height: 64, width: 208}\n"), "cpu");
  GEO_EXPECT_THROW_WITH(evaluate(f, untrained), second, "must have one size");
}

// Depth at an unknown scale (the dense truth x 0.3) gets its metres back from the camera's height
// above the road (geo_synth's 1.65 m), without ground truth: the same scale as median scaling to
// within 2%, and errors at most 10% above median scaling's; --scaling none keeps the 0.3.
TEST(Protocols, CameraHeightScalingRecoversTheScaleWithoutGroundTruth) {
  const auto root = test::fresh_dir("protocols_height");
  std::filesystem::rename(test::write_small_world("protocols_height_world", 6, 1, 6), root + "/world");
  const auto tests = read_lines(root + "/world/raw/splits/eigen/test_files.txt");
  std::filesystem::create_directories(root + "/depth");
  for (size_t i = 0; i < tests.size(); ++i) {
    const auto d = tests[i].substr(0, tests[i].find("/image_02"));
    const auto f = tests[i].substr(tests[i].rfind('/') + 1);
    const auto truth = read_depth_png(root + "/world/raw/" + d + "/proj_depth/groundtruth/image_02/" + f);
    write_depth_png(root + "/depth/" + zero_padded(static_cast<long long>(i), 6) + ".png", truth * 0.3);
  }
  EvalOptions e;
  e.split = "eigen";
  e.data_root = root + "/world";
  const std::string scaled = root + "/depth";
  const auto median = score_files(e, scaled);
  EXPECT_EQ(median.scaling, "median");
  EXPECT_NEAR(metric_of(median, "scale_ratio_median"), 1 / 0.3, 0.05);
  e.scaling = DepthScaling::kCameraHeight;
  const auto height = score_files(e, scaled);
  EXPECT_EQ(count_of(height, "images_without_road_plane"), 0);
  EXPECT_NEAR(metric_of(height, "scale_agreement_median"), 1.0, 0.02);
  // Not worse than median scaling by more than 10% (here better: the height gives the exact 1/0.3,
  // while the median against Velodyne points is off by the scanner's 27 cm).
  EXPECT_LT(metric_of(height, "abs_rel"), 1.1 * metric_of(median, "abs_rel"));
  EXPECT_NE(height.json().find("\"scaling\": \"camera-height 1.650000 m\""), std::string::npos) << height.json();
  std::printf("camera-height scaling: abs_rel %.4f (median scaling %.4f), scale agreement %.4f +- %.4f\n",
              metric_of(height, "abs_rel"), metric_of(median, "abs_rel"), metric_of(height, "scale_agreement_median"),
              metric_of(height, "scale_agreement_std"));
  // The height comes from the world's record (geo_synth's camera_height.txt) unless given.
  EXPECT_EQ(test::read_file(root + "/world/camera_height.txt"), "1.65\n");
  test::write_text(root + "/world/camera_height.txt", "3.3\n");
  EXPECT_NEAR(metric_of(score_files(e, scaled), "scale_agreement_median"),
              2 * metric_of(height, "scale_agreement_median"), 1e-9);
  e.camera_height = 1.65;
  EXPECT_NEAR(metric_of(score_files(e, scaled), "scale_agreement_median"), metric_of(height, "scale_agreement_median"),
              1e-12);
  e.scaling = DepthScaling::kNone;
  EXPECT_GT(metric_of(score_files(e, scaled), "abs_rel"), 0.6);  // 1 - 0.3, before the clamp
}

// GeoNet trains each table's model on data disjoint from its test set. geo_eval reads the training
// data from the checkpoint's config: the shipped eigen_zhou lists hold the drive of odometry 09
// (2011_09_30_drive_0033), odometry 00-08 do not.
TEST(Protocols, AModelTrainedOnTestDrivesIsWarnedAndRecorded) {
  const auto root = test::fresh_dir("overlap");
  const auto world = test::write_small_world("overlap_world", 4, 1, 6);
  // The world's odometry sequence outside the world (no geo_synth README): read as KITTI's 09.
  std::filesystem::copy(world + "/odometry", root + "/odometry", std::filesystem::copy_options::recursive);
  // A KITTI root without its own split lists: training used the shipped ones.
  std::filesystem::create_directories(root + "/kitti_raw");
  auto checkpoint_of = [&](const std::string& data, const std::string& name,
                           const std::string& data_root = "/kitti_raw", std::vector<std::string> init_configs = {}) {
    const Config c = parse_config(
        "model: {encoder_depth: 18}\ndata: {height: 64, width: 208, root: " + root + data_root + ", " + data + "}\n",
        name + ".yaml");
    torch::manual_seed(1);
    Networks nets = Networks::create(NetworkSpec::of(c), false);
    torch::serialize::OutputArchive a;
    write_checkpoint(a, CheckpointContents{nets, nullptr, TrainState{}, c, std::move(init_configs)});
    save_archive(a, root + "/" + name + ".pt");
    return root + "/" + name + ".pt";
  };
  EvalOptions e;
  e.split = "odometry";
  e.data_root = root + "/odometry";
  Predictor depth_model(checkpoint_of("split: eigen_zhou", "eigen_zhou"), "cpu");
  const auto leaky = evaluate(e, depth_model);
  EXPECT_EQ(leaky.test_drives, std::vector<std::string>{"2011_09_30_drive_0033"});
  EXPECT_EQ(leaky.test_drives_in_training, std::vector<std::string>{"2011_09_30_drive_0033"});
  EXPECT_NE(leaky.json().find("\"test_drives_in_training\": [\"2011_09_30_drive_0033\"]"), std::string::npos)
      << leaky.json();
  test::write_text(root + "/leaky.json", leaky.json());
  EXPECT_EQ(read_result(root + "/leaky.json").test_drives_in_training, leaky.test_drives_in_training);
  EXPECT_NE(format_results({leaky}, {"leaky"}).find("trained on 1 of the 1 test drives: 2011_09_30_drive_0033"),
            std::string::npos);
  Predictor pose_model(checkpoint_of("split: odometry", "odometry"), "cpu");
  const auto clean = evaluate(e, pose_model);
  EXPECT_TRUE(clean.test_drives_in_training.empty());
  EXPECT_TRUE(clean.training_drives_unknown.empty());
  // Clean itself, but initialised from a checkpoint that trained on the test drive: the init chain
  // is followed (the flow table's stage 1 on eigen_zhou); a link without a config is unknown.
  const std::string leaky_init = to_yaml(CheckpointFile(root + "/eigen_zhou.pt").config().value());
  Predictor chained(checkpoint_of("split: odometry", "chained", "/kitti_raw",
                                  {to_yaml(CheckpointFile(root + "/odometry.pt").config().value()), leaky_init}),
                    "cpu");
  EXPECT_EQ(evaluate(e, chained).test_drives_in_training, std::vector<std::string>{"2011_09_30_drive_0033"});
  Predictor from_model(checkpoint_of("split: odometry", "from_model", "/kitti_raw", {"unknown: m.pt is a model file"}),
                       "cpu");
  const auto unknown_init = evaluate(e, from_model);
  EXPECT_NE(unknown_init.training_drives_unknown.find("m.pt is a model file"), std::string::npos)
      << unknown_init.training_drives_unknown;
  // A root that is not here (a relative one from another folder): unknown, never "none".
  Predictor elsewhere(checkpoint_of("split: eigen_zhou", "elsewhere", "/moved_away"), "cpu");
  const auto unknown = evaluate(e, elsewhere);
  EXPECT_TRUE(unknown.test_drives_in_training.empty());
  EXPECT_NE(
      unknown.training_drives_unknown.find("the training data root '" + root + "/moved_away' is not a folder here"),
      std::string::npos)
      << unknown.training_drives_unknown;
  // A geo_synth world's odometry/ and kitti2015/ scenes are no raw drive: nothing to compare.
  e.data_root = world;
  EXPECT_TRUE(evaluate(e, depth_model).test_drives.empty());
  // An untrained model (no training config) says it cannot tell.
  Predictor untrained(parse_config("model: {encoder_depth: 18}\ndata: {height: 64, width: 208}\n"), "cpu");
  EXPECT_FALSE(evaluate(e, untrained).training_drives_unknown.empty());
}

}  // namespace
}  // namespace geo
