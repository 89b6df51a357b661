#include "losses/consistency.h"

#include <gtest/gtest.h>

namespace {

TEST(Occlusion, ConsistentFlowsAreVisibleEverywhere) {
  // Constant translation (u, v) forward and (-u, -v) backward: W_f + W_b(p + W_f) = 0.
  auto fw = torch::zeros({1, 2, 8, 10}, torch::kFloat64);
  fw.select(1, 0).fill_(1.5);
  fw.select(1, 1).fill_(-0.5);
  const auto bw = -fw;
  const auto bw_at_fw = geo::backward_at_forward(fw, bw, geo::OutOfView::kBorder);
  EXPECT_EQ(geo::visibility_mask(fw, bw_at_fw, 0.01, 0.5).min().item<double>(), 1.0);
  const auto c = geo::geometric_consistency(fw, bw_at_fw, 3.0, 0.05, 0, true);
  EXPECT_EQ(c.loss.item<double>(), 0.0);
  EXPECT_EQ(c.mask.min().item<double>(), 1.0);
}

TEST(Occlusion, DisagreeingRegionIsOccluded) {
  auto fw = torch::zeros({1, 2, 8, 8}, torch::kFloat64);
  fw.select(1, 0).fill_(1.0);
  auto bw = -fw.clone();
  // Backward flow of a 2x2 block says something else (e.g. a foreground object): +5 px in u.
  bw.select(1, 0).narrow(1, 2, 2).narrow(2, 4, 2).fill_(5.0);
  const auto bw_at_fw = geo::backward_at_forward(fw, bw, geo::OutOfView::kBorder);
  const auto vis = geo::visibility_mask(fw, bw_at_fw, 0.01, 0.5);
  // Target pixels (x, y) with x + 1 in {4, 5} and y in {2, 3} land on the block: x in {3, 4}.
  // There |W_f + W_b|^2 = 36 > 0.01 (1 + 25) + 0.5.
  EXPECT_EQ(vis[0][0][2][3].item<double>(), 0.0);
  EXPECT_EQ(vis[0][0][3][4].item<double>(), 0.0);
  EXPECT_EQ(vis.sum().item<double>(), 64 - 4);
  // Hand-computed consistency: diff = (6, 0) on 4 pixels, 0 elsewhere. Bound max(3, 0.05*1) = 3
  // and 6 > 3, so those pixels are excluded and the loss is 0 ...
  auto c = geo::geometric_consistency(fw, bw_at_fw, 3.0, 0.05, 0, true);
  EXPECT_EQ(c.mask.sum().item<double>(), 60);
  EXPECT_DOUBLE_EQ(c.loss.item<double>(), 0.0);
  // ... while a = 10 keeps them: loss = mean over (u,v) and 64 pixels of |diff| = 4*6 / (2*64).
  c = geo::geometric_consistency(fw, bw_at_fw, 10.0, 0.05, 0, true);
  EXPECT_NEAR(c.loss.item<double>(), 24.0 / 128.0, 1e-12);
  // GeoNet's 2^s factor at scale 2: 6 * 4 = 24 > 10, excluded again.
  c = geo::geometric_consistency(fw, bw_at_fw, 10.0, 0.05, 2, true);
  EXPECT_EQ(c.mask.sum().item<double>(), 60);
  c = geo::geometric_consistency(fw, bw_at_fw, 10.0, 0.05, 2, false);
  EXPECT_EQ(c.mask.sum().item<double>(), 64);
}

TEST(Occlusion, FlowLeavingTheImageIsOccludedWithGeoNetsSampler) {
  // u = 4 forward, -4 backward on an 8x8 image. Pixels x >= 3 land on x + 4 >= 7 = W-1, outside
  // GeoNet's sampler: W_b(p + W_f) = 0 there, |W_f|^2 = 16 > 0.01 * 16 + 0.5 -> occluded. The
  // border sampler reads the edge's -4 and keeps them visible. The last row (y = H-1) is outside
  // GeoNet's sampler too: every pixel there is occluded.
  auto fw = torch::zeros({1, 2, 8, 8}, torch::kFloat64);
  fw.select(1, 0).fill_(4.0);
  const auto bw = -fw;
  const auto zero = geo::visibility_mask(fw, geo::backward_at_forward(fw, bw, geo::OutOfView::kZero), 0.01, 0.5);
  EXPECT_EQ(zero.sum().item<double>(), 7 * 3);
  EXPECT_EQ(zero.narrow(3, 0, 3).narrow(2, 0, 7).min().item<double>(), 1.0);
  const auto border = geo::visibility_mask(fw, geo::backward_at_forward(fw, bw, geo::OutOfView::kBorder), 0.01, 0.5);
  EXPECT_EQ(border.sum().item<double>(), 64);
}

TEST(Consistency, GradientFlowsIntoTheFlowsButNotTheBound) {
  torch::manual_seed(12);
  const auto fw = (torch::randn({1, 2, 6, 6}, torch::kFloat64)).requires_grad_();
  const auto bw = (torch::randn({1, 2, 6, 6}, torch::kFloat64)).requires_grad_();
  const auto c =
      geo::geometric_consistency(fw, geo::backward_at_forward(fw, bw, geo::OutOfView::kBorder), 3.0, 0.05, 0, true);
  c.loss.backward();
  EXPECT_FALSE(c.mask.requires_grad());
  EXPECT_TRUE(torch::isfinite(fw.grad()).all().item<bool>());
  EXPECT_GT(bw.grad().abs().sum().item<double>(), 0);
}

TEST(Consistency, MalformedShapesThrow) {
  EXPECT_THROW(geo::visibility_mask(torch::zeros({1, 3, 4, 4}), torch::zeros({1, 3, 4, 4}), 0.01, 0.5), c10::Error);
  EXPECT_THROW(geo::backward_at_forward(torch::zeros({1, 2, 4, 4}), torch::zeros({2, 2, 4, 4}), geo::OutOfView::kZero),
               c10::Error);
}

}  // namespace
