#include "geometry/camera.h"

#include <gtest/gtest.h>

#include "geometry/pose.h"

namespace {


torch::Tensor intrinsics(double fx, double fy, double cx, double cy, int64_t batch = 1) {
  return torch::tensor({fx, 0., cx, 0., fy, cy, 0., 0., 1.}, torch::kFloat64).view({1, 3, 3}).repeat({batch, 1, 1});
}

TEST(Camera, IntrinsicsPerScaleDivideByPowersOfTwo) {
  const auto Ks = geo::intrinsics_pyramid(intrinsics(720, 700, 600, 180), 4);
  ASSERT_EQ(Ks.size(), 4u);
  EXPECT_DOUBLE_EQ(Ks[3][0][0][0].item<double>(), 90.0);
  EXPECT_DOUBLE_EQ(Ks[3][0][1][1].item<double>(), 87.5);
  EXPECT_DOUBLE_EQ(Ks[3][0][0][2].item<double>(), 75.0);
  EXPECT_DOUBLE_EQ(Ks[3][0][1][2].item<double>(), 22.5);
  EXPECT_DOUBLE_EQ(Ks[3][0][2][2].item<double>(), 1.0);
}

TEST(Camera, ProjectOfBackProjectIsThePixelGrid) {
  torch::manual_seed(5);
  const auto K = intrinsics(50, 45, 15.5, 9.5, 2);
  const auto depth = torch::rand({2, 1, 10, 16}, torch::kFloat64) * 50 + 1;
  const auto pix = geo::project(geo::back_project(depth, K), K);
  const auto grid = geo::pixel_grid(10, 16, torch::kFloat64).narrow(1, 0, 2).expand({2, 2, 10, 16});
  // Residual ~1e-9: the projection divides by z + 1e-10 (GeoNet) and K is inverted numerically.
  EXPECT_LT((pix - grid).abs().max().item<double>(), 1e-8);
  // back_project keeps the depth as z.
  EXPECT_LT((geo::back_project(depth, K).narrow(1, 2, 1) - depth).abs().max().item<double>(), 1e-12);
}

TEST(Camera, RigidFlowOfAFrontoParallelPlaneUnderTranslationIsTheClosedForm) {
  // Plane at depth Z, camera translation t (src_from_tgt, no rotation):
  //   u = fx tx/(Z+tz) + (x - cx)(Z/(Z+tz) - 1),  v = fy ty/(Z+tz) + (y - cy)(Z/(Z+tz) - 1).
  const double fx = 100, fy = 90, cx = 20, cy = 8, Z = 10, tx = 0.5, ty = -0.2, tz = 1.0;
  const auto K = intrinsics(fx, fy, cx, cy);
  const auto depth = torch::full({1, 1, 16, 40}, Z, torch::kFloat64);
  auto pose = torch::zeros({1, 6}, torch::kFloat64);
  pose[0][0] = tx;
  pose[0][1] = ty;
  pose[0][2] = tz;
  const auto flow = geo::rigid_flow(depth, geo::pose_vec_to_matrix(pose), K);
  const auto grid = geo::pixel_grid(16, 40, torch::kFloat64);
  const double r = Z / (Z + tz) - 1;
  const auto u = fx * tx / (Z + tz) + (grid[0][0] - cx) * r;
  const auto v = fy * ty / (Z + tz) + (grid[0][1] - cy) * r;
  EXPECT_LT((flow[0][0] - u).abs().max().item<double>(), 1e-9);
  EXPECT_LT((flow[0][1] - v).abs().max().item<double>(), 1e-9);
}

TEST(Camera, ZeroMotionGivesZeroFlowAndBackwardInvertsForward) {
  torch::manual_seed(6);
  const auto K = intrinsics(30, 30, 8, 6, 2);
  const auto depth = torch::rand({2, 1, 12, 16}, torch::kFloat64) * 20 + 2;
  const auto eye = torch::eye(4, torch::kFloat64).expand({2, 4, 4});
  EXPECT_LT(geo::rigid_flow(depth, eye, K).abs().max().item<double>(), 1e-8);
  // Fronto-parallel plane under lateral translation: the backward flow is the exact negation.
  const auto plane = torch::full({2, 1, 12, 16}, 10.0, torch::kFloat64);
  auto pose = torch::zeros({2, 6}, torch::kFloat64);
  pose.select(1, 0).fill_(0.3);
  const auto T = geo::pose_vec_to_matrix(pose);
  const auto fwd = geo::rigid_flow(plane, T, K);
  const auto bwd = geo::rigid_flow(plane, geo::inverse_transform(T), K);
  EXPECT_LT((fwd + bwd).abs().max().item<double>(), 1e-8);  // lateral motion: negation
}

TEST(Camera, MalformedShapesNameTheArgument) {
  try {
    geo::back_project(torch::ones({1, 2, 4, 4}), torch::eye(3).unsqueeze(0));
    FAIL();
  } catch (const c10::Error& e) {
    EXPECT_NE(std::string(e.what_without_backtrace()).find("depth must have shape"), std::string::npos);
  }
  EXPECT_THROW(geo::rigid_flow(torch::ones({2, 1, 4, 4}), torch::eye(4).expand({1, 4, 4}),
                               torch::eye(3).expand({2, 3, 3})),
               c10::Error);
}

}  // namespace
