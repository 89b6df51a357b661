#include "geometry/warp.h"

#include <gtest/gtest.h>

namespace {

const auto kDouble = torch::TensorOptions().dtype(torch::kFloat64);

TEST(Warp, ZeroFlowReturnsTheInput) {
  torch::manual_seed(7);
  const auto img = torch::rand({2, 3, 9, 13}, kDouble);
  const auto out = geo::warp(img, torch::zeros({2, 2, 9, 13}, kDouble));
  EXPECT_LT((out.image - img).abs().max().item<double>(), 1e-12);
  EXPECT_EQ(out.valid.min().item<double>(), 1.0);
}

TEST(Warp, IntegerFlowShiftsTheInteriorExactly) {
  torch::manual_seed(8);
  const auto img = torch::rand({1, 2, 10, 12}, kDouble);
  auto flow = torch::zeros({1, 2, 10, 12}, kDouble);
  flow.select(1, 0).fill_(2);   // u = +2: out(x, y) = img(x + 2, y - 1)
  flow.select(1, 1).fill_(-1);  // v = -1
  const auto out = geo::warp(img, flow);
  // Interior: rows 1..9, columns 0..9 sample inside the image.
  const auto got = out.image.narrow(2, 1, 9).narrow(3, 0, 10);
  const auto want = img.narrow(2, 0, 9).narrow(3, 2, 10);
  EXPECT_LT((got - want).abs().max().item<double>(), 1e-12);
  EXPECT_EQ(out.valid.narrow(2, 1, 9).narrow(3, 0, 10).min().item<double>(), 1.0);
  // Row 0 samples y = -1 and columns 10, 11 sample x = 12, 13: outside, marked invalid.
  EXPECT_EQ(out.valid.narrow(2, 0, 1).max().item<double>(), 0.0);
  EXPECT_EQ(out.valid.narrow(3, 10, 2).max().item<double>(), 0.0);
  EXPECT_EQ(out.valid.sum().item<double>(), 9 * 10);
}

TEST(Warp, HalfPixelFlowInterpolatesBilinearly) {
  const auto img = torch::arange(12, kDouble).view({1, 1, 3, 4});
  auto flow = torch::zeros({1, 2, 3, 4}, kDouble);
  flow.select(1, 0).fill_(0.5);
  const auto out = geo::warp(img, flow);
  EXPECT_NEAR(out.image[0][0][1][1].item<double>(), 5.5, 1e-12);  // between 5 and 6
}

TEST(Warp, FlowLeavingTheImageIsInvalid) {
  const auto img = torch::ones({1, 1, 4, 4}, kDouble);
  const auto flow = torch::full({1, 2, 4, 4}, 100.0, kDouble);
  const auto out = geo::warp(img, flow);
  EXPECT_EQ(out.valid.max().item<double>(), 0.0);
  EXPECT_EQ(out.image.min().item<double>(), 1.0);  // border-clamped samples (GeoNet)
}

TEST(Warp, GradientsReachImageAndFlow) {
  torch::manual_seed(9);
  const auto img = torch::rand({1, 3, 6, 8}, kDouble).requires_grad_();
  const auto flow = (torch::rand({1, 2, 6, 8}, kDouble) * 2 - 1).requires_grad_();
  geo::warp(img, flow).image.sum().backward();
  EXPECT_GT(img.grad().abs().sum().item<double>(), 0);
  EXPECT_GT(flow.grad().abs().sum().item<double>(), 0);
  EXPECT_TRUE(torch::isfinite(flow.grad()).all().item<bool>());
}

TEST(Warp, MalformedFlowNamesTheArgument) {
  try {
    geo::warp(torch::zeros({1, 3, 4, 4}), torch::zeros({1, 3, 4, 4}));
    FAIL();
  } catch (const c10::Error& e) {
    EXPECT_NE(std::string(e.what_without_backtrace()).find("flow must have shape [1, 2, 4, 4]"),
              std::string::npos)
        << e.what_without_backtrace();
  }
}

}  // namespace
