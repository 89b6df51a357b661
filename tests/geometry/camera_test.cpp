#include "geometry/camera.h"

#include <gtest/gtest.h>

#include "geometry/pose.h"

#include <array>
#include <utility>
#include <vector>

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

TEST(Camera, Inverse3x3IsTheInverse) {
  // A camera: [1/fx 0 -cx/fx; 0 1/fy -cy/fy; 0 0 1], exactly for powers of two.
  const auto K = intrinsics(4, 8, 2, 16);
  const auto hand = torch::tensor({0.25, 0., -0.5, 0., 0.125, -2., 0., 0., 1.}, torch::kFloat64).view({1, 3, 3});
  EXPECT_TRUE(torch::equal(geo::inverse_3x3(K), hand));
  // Any invertible matrix, batched: M times its inverse is the identity; gradients flow to M.
  torch::manual_seed(3);
  const auto M = (torch::randn({5, 3, 3}, torch::kFloat64) + 3 * torch::eye(3, torch::kFloat64)).requires_grad_();
  const auto inv = geo::inverse_3x3(M);
  EXPECT_LT((M.matmul(inv) - torch::eye(3, torch::kFloat64)).abs().max().item<double>(), 1e-12);
  inv.sum().backward();
  EXPECT_TRUE(torch::allclose(
      M.grad(), -inv.transpose(1, 2).matmul(torch::ones({5, 3, 3}, torch::kFloat64)).matmul(inv.transpose(1, 2)), 1e-9,
      1e-12));
  EXPECT_THROW(geo::inverse_3x3(torch::zeros({2, 3, 4})), c10::Error);
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
  EXPECT_THROW(
      geo::rigid_flow(torch::ones({2, 1, 4, 4}), torch::eye(4).expand({1, 4, 4}), torch::eye(3).expand({2, 3, 3})),
      c10::Error);
}

}  // namespace

namespace {

// A camera point's pixel in a frame, (u, v) = (fx x/z + cx, fy y/z + cy).
std::pair<double, double> pixel_of(const torch::Tensor& K, double x, double y, double z) {
  return {K[0][0].item<double>() * x / z + K[0][2].item<double>(),
          K[1][1].item<double>() * y / z + K[1][2].item<double>()};
}

}  // namespace

TEST(Camera, CropToAspectKeepsTheLargestWindowOfTheTrainingShape) {
  // 1920x1080 (16:9) for 416x128: every column, 1920*128/416 = 590.8 -> 591 rows, centred:
  // (1080 - 591) / 2 = 244.5 -> 245.
  const auto w = geo::crop_to_aspect(1920, 1080, 416, 128);
  EXPECT_EQ(w.x0, 0);
  EXPECT_EQ(w.width, 1920);
  EXPECT_EQ(w.height, 591);
  EXPECT_EQ(w.y0, 245);
  EXPECT_EQ(geo::crop_to_aspect(1920, 1080, 416, 128, 0.0).y0, 0);
  EXPECT_EQ(geo::crop_to_aspect(1920, 1080, 416, 128, 1.0).y0, 1080 - 591);
  // Wider than the target (3000x500 for 416x128 = 3.25): 500*416/128 = 1625 columns, centred.
  const auto v = geo::crop_to_aspect(3000, 500, 416, 128);
  EXPECT_EQ(v.width, 1625);
  EXPECT_EQ(v.x0, (3000 - 1625) / 2);
  EXPECT_EQ(v.height, 500);
  // Already the shape: the whole frame.
  const auto same = geo::crop_to_aspect(832, 256, 416, 128);
  EXPECT_EQ(same.x0, 0);
  EXPECT_EQ(same.y0, 0);
  EXPECT_EQ(same.width, 832);
  EXPECT_EQ(same.height, 256);
}

TEST(Camera, CroppedResizedIntrinsicsProjectWherePixelsGo) {
  const auto K = intrinsics(1000, 990, 955, 530)[0];
  const geo::CropWindow w{10, 245, 1900, 591};
  const auto Kc = geo::cropped_resized_intrinsics(K, w, 128, 416);
  const double sx = 416.0 / 1900, sy = 128.0 / 591;
  EXPECT_NEAR(Kc[0][0].item<double>(), 1000 * sx, 1e-12);
  EXPECT_NEAR(Kc[1][1].item<double>(), 990 * sy, 1e-12);
  EXPECT_NEAR(Kc[0][2].item<double>(), (955 - 10) * sx, 1e-12);
  EXPECT_NEAR(Kc[1][2].item<double>(), (530 - 245) * sy, 1e-12);
  // Any point: its pixel in the training frame is its original pixel moved by the crop, then scaled.
  for (const auto& p : std::vector<std::array<double, 3>>{{1.0, -0.5, 7.0}, {-3.0, 1.2, 20.0}, {0.1, 0.3, 2.5}}) {
    const auto [u, v] = pixel_of(K, p[0], p[1], p[2]);
    const auto [uc, vc] = pixel_of(Kc, p[0], p[1], p[2]);
    EXPECT_NEAR(uc, (u - 10) * sx, 1e-9);
    EXPECT_NEAR(vc, (v - 245) * sy, 1e-9);
  }
  // A plain resize is the no-crop window.
  const auto Kr = geo::resized_intrinsics(K, 1080, 1920, 128, 416);
  EXPECT_TRUE(torch::allclose(Kr, geo::cropped_resized_intrinsics(K, {0, 0, 1920, 1080}, 128, 416)));
}
