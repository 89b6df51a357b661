#include "geometry/warp.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

namespace {

TEST(Warp, ZeroFlowReturnsTheInput) {
  torch::manual_seed(7);
  const auto img = torch::rand({2, 3, 9, 13}, torch::kFloat64);
  const auto out = geo::warp(img, torch::zeros({2, 2, 9, 13}, torch::kFloat64), geo::OutOfView::kBorder);
  EXPECT_LT((out.image - img).abs().max().item<double>(), 1e-12);
  EXPECT_EQ(out.valid.min().item<double>(), 1.0);
}

TEST(Warp, IntegerFlowShiftsTheInteriorExactly) {
  torch::manual_seed(8);
  const auto img = torch::rand({1, 2, 10, 12}, torch::kFloat64);
  auto flow = torch::zeros({1, 2, 10, 12}, torch::kFloat64);
  flow.select(1, 0).fill_(2);   // u = +2: out(x, y) = img(x + 2, y - 1)
  flow.select(1, 1).fill_(-1);  // v = -1
  const auto out = geo::warp(img, flow, geo::OutOfView::kBorder);
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
  const auto img = torch::arange(12, torch::kFloat64).view({1, 1, 3, 4});
  auto flow = torch::zeros({1, 2, 3, 4}, torch::kFloat64);
  flow.select(1, 0).fill_(0.5);
  for (auto mode : {geo::OutOfView::kZero, geo::OutOfView::kBorder}) {
    const auto out = geo::warp(img, flow, mode);
    EXPECT_NEAR(out.image[0][0][1][1].item<double>(), 5.5, 1e-12);  // between 5 and 6
  }
}

TEST(Warp, FlowLeavingTheImageIsInvalidAndClampedInBorderMode) {
  const auto img = torch::ones({1, 1, 4, 4}, torch::kFloat64);
  const auto flow = torch::full({1, 2, 4, 4}, 100.0, torch::kFloat64);
  const auto out = geo::warp(img, flow, geo::OutOfView::kBorder);
  EXPECT_EQ(out.valid.max().item<double>(), 0.0);
  EXPECT_EQ(out.image.min().item<double>(), 1.0);  // border-clamped samples
}

// GeoNet's bilinear_sampler (utils.py), written out for one coordinate pair: x0 = floor(x),
// x1 = x0 + 1, both clipped to [0, W-1]; weights x1_safe - x and x - x0_safe (likewise y).
double geonet_sample(const torch::Tensor& img, double x, double y) {
  const int64_t H = img.size(0), W = img.size(1);
  const double x0 = std::floor(x), y0 = std::floor(y);
  auto clip = [](double v, int64_t n) { return std::min(std::max(v, 0.0), static_cast<double>(n - 1)); };
  const double x0s = clip(x0, W), x1s = clip(x0 + 1, W), y0s = clip(y0, H), y1s = clip(y0 + 1, H);
  auto at = [&](double yy, double xx) {
    return img[static_cast<int64_t>(yy)][static_cast<int64_t>(xx)].item<double>();
  };
  const double wx0 = x1s - x, wx1 = x - x0s, wy0 = y1s - y, wy1 = y - y0s;
  return wx0 * wy0 * at(y0s, x0s) + wx0 * wy1 * at(y1s, x0s) + wx1 * wy0 * at(y0s, x1s) + wx1 * wy1 * at(y1s, x1s);
}

TEST(Warp, ZeroModeIsGeoNetsSamplerOutsideAndOnTheLastColumn) {
  // 3x5 image, values 1..15. Target pixel (x=1, y=1) sampled at x = 1 + u.
  const auto img = torch::arange(1, 16, torch::kFloat64).view({1, 1, 3, 5});
  for (double u : {0.25, 2.5, 3.0, 3.5, 3.999, 4.0, -1.5, -0.5, -1.0, 10.0}) {
    auto flow = torch::zeros({1, 2, 3, 5}, torch::kFloat64);
    flow.select(1, 0).fill_(u);
    const auto out = geo::warp(img, flow, geo::OutOfView::kZero);
    const double x = 1 + u;
    const double want = geonet_sample(img[0][0], x, 1.0);
    EXPECT_NEAR(out.image[0][0][1][1].item<double>(), want, 1e-12) << "x = " << x;
    // Hand-computed: inside [0, W-1) = [0, 4) bilinear, else 0 (x = W-1 = 4 included).
    const double hand = (x >= 0 && x < 4) ? 6 + x : 0.0;  // row 1 holds 6..10 at x = 0..4
    EXPECT_NEAR(out.image[0][0][1][1].item<double>(), hand, 1e-12) << "x = " << x;
    EXPECT_EQ(out.valid[0][0][1][1].item<double>(), (x >= 0 && x < 4) ? 1.0 : 0.0) << "x = " << x;
  }
  // x = W - 0.5 and x = W - 1 give 0 (GeoNet's sampler's two edge cases); the border sampler keeps 10.
  for (double x : {4.5, 4.0}) {
    auto flow = torch::zeros({1, 2, 3, 5}, torch::kFloat64);
    flow.select(1, 0).fill_(x - 1);
    EXPECT_EQ(geo::warp(img, flow, geo::OutOfView::kZero).image[0][0][1][1].item<double>(), 0.0);
    EXPECT_EQ(geo::warp(img, flow, geo::OutOfView::kBorder).image[0][0][1][1].item<double>(), 10.0);
  }
  // The last row y = H-1 = 2 is out of view too.
  auto down = torch::zeros({1, 2, 3, 5}, torch::kFloat64);
  down.select(1, 1).fill_(1.0);
  EXPECT_EQ(geo::warp(img, down, geo::OutOfView::kZero).image[0][0][1][1].item<double>(), 0.0);
}

TEST(Warp, ZeroModeHasNoGradientOutOfView) {
  const auto img = torch::rand({1, 1, 3, 5}, torch::kFloat64).requires_grad_();
  auto flow = torch::zeros({1, 2, 3, 5}, torch::kFloat64);
  flow.select(1, 0).fill_(7.3);  // every pixel leaves the image
  flow.requires_grad_();
  geo::warp(img, flow, geo::OutOfView::kZero).image.sum().backward();
  EXPECT_EQ(img.grad().abs().sum().item<double>(), 0.0);
  EXPECT_EQ(flow.grad().abs().sum().item<double>(), 0.0);
}

TEST(Warp, GradientsReachImageAndFlow) {
  torch::manual_seed(9);
  const auto img = torch::rand({1, 3, 6, 8}, torch::kFloat64).requires_grad_();
  const auto flow = (torch::rand({1, 2, 6, 8}, torch::kFloat64) * 2 - 1).requires_grad_();
  geo::warp(img, flow, geo::OutOfView::kZero).image.sum().backward();
  EXPECT_GT(img.grad().abs().sum().item<double>(), 0);
  EXPECT_GT(flow.grad().abs().sum().item<double>(), 0);
  EXPECT_TRUE(torch::isfinite(flow.grad()).all().item<bool>());
}

TEST(Warp, MalformedFlowNamesTheArgument) {
  try {
    geo::warp(torch::zeros({1, 3, 4, 4}), torch::zeros({1, 3, 4, 4}), geo::OutOfView::kZero);
    FAIL();
  } catch (const c10::Error& e) {
    EXPECT_NE(std::string(e.what_without_backtrace()).find("flow must have shape [1, 2, 4, 4]"), std::string::npos)
        << e.what_without_backtrace();
  }
}

}  // namespace
