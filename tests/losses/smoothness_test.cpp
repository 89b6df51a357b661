#include "losses/smoothness.h"

#include <gtest/gtest.h>

#include <cmath>

namespace {

TEST(Smoothness, ConstantMapIsZero) {
  torch::manual_seed(11);
  EXPECT_EQ(geo::edge_aware_smoothness(torch::full({2, 1, 5, 6}, 3.0, torch::kFloat64),
                                       torch::rand({2, 3, 5, 6}, torch::kFloat64))
                .item<double>(),
            0.0);
}

TEST(Smoothness, HandComputed4x4Case) {
  // d(x, y) = x (dx = -1 everywhere, dy = 0). Image: columns 0,0.5,1,1.5 in every channel, so
  // |dx I| = 0.5 and the x weight is exp(-0.5); rows are equal so dy I = 0.
  // Loss = mean(|dx d| e^-0.5) + mean(0) = e^-0.5.
  auto d = torch::arange(4, torch::kFloat64).view({1, 1, 1, 4}).expand({1, 1, 4, 4}).contiguous();
  auto img = (torch::arange(4, torch::kFloat64) * 0.5).view({1, 1, 1, 4}).expand({1, 3, 4, 4}).contiguous();
  EXPECT_NEAR(geo::edge_aware_smoothness(d, img).item<double>(), std::exp(-0.5), 1e-12);
  // A flat image (weight 1) and d(x, y) = 2y: dy = -2 on 3x4 pairs -> loss 2.
  auto d2 = (torch::arange(4, torch::kFloat64) * 2).view({1, 1, 4, 1}).expand({1, 1, 4, 4}).contiguous();
  EXPECT_NEAR(geo::edge_aware_smoothness(d2, torch::zeros({1, 3, 4, 4}, torch::kFloat64)).item<double>(), 2.0, 1e-12);
  // Flow (2 channels): u = x, v = 2y on a flat image -> (1 + 2) / 2 = 1.5: the mean of the u and v
  // terms, as GeoNet's compute_flow_smooth_loss (sum over i of compute_smooth_loss, divided by 2).
  const auto flow = torch::cat({d, d2}, 1);
  EXPECT_NEAR(geo::edge_aware_smoothness(flow, torch::zeros({1, 3, 4, 4}, torch::kFloat64)).item<double>(), 1.5, 1e-12);
}

TEST(Smoothness, MismatchedImageThrows) {
  EXPECT_THROW(geo::edge_aware_smoothness(torch::zeros({1, 1, 4, 4}), torch::zeros({1, 3, 4, 5})), c10::Error);
}

}  // namespace
