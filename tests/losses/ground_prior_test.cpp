#include "losses/ground_prior.h"

#include <gtest/gtest.h>

namespace {

// A level camera 2 units above a flat road: fy = 4, cy = 1.5 on an 8x4 image. Row v sees the road at
// disparity (v - 1.5) / (4 * 2); rows 2..7 lie within 20 camera heights (slope > 0.05): 24 pixels.
constexpr int64_t kH = 8, kW = 4;
torch::Tensor camera() { return torch::tensor({4., 0., 2., 0., 4., 1.5, 0., 0., 1.}, torch::kFloat64).view({1, 3, 3}); }
torch::Tensor road_disparity() {
  auto d = torch::full({1, 1, kH, kW}, 0.01, torch::kFloat64);  // above the horizon: far
  for (int64_t v = 2; v < kH; ++v) d[0][0][v].fill_((static_cast<double>(v) - 1.5) / 8.0);
  return d;
}

TEST(GroundPrior, ARoadExactlyOnItsPlaneCostsNothing) {
  EXPECT_DOUBLE_EQ(geo::ground_prior(road_disparity(), camera()).item<double>(), 0.0);
}

TEST(GroundPrior, PixelsBeyondTheRoadArePenalisedByHowFarBeyond) {
  auto d = road_disparity();
  d[0][0][6][1] = 0.0;                  // infinitely far: 1 - 0.05 - 0 (the fit ignores it)
  d[0][0][5][2] = 0.5 * (5 - 1.5) / 8;  // twice the road's depth: 1 - 0.05 - 0.5
  d[0][0][4][3] = 2.0 * (4 - 1.5) / 8;  // in front of the road: nothing
  d[0][0][1][0] = 0.0;                  // above the bounded rows: nothing
  d.requires_grad_(true);
  const auto loss = geo::ground_prior(d, camera());
  EXPECT_NEAR(loss.item<double>(), (0.95 + 0.45) / 24.0, 1e-12);
  loss.backward();
  // d/d disp of relu(0.95 - disp / road) / 24 = -1 / (road * 24) where it is positive.
  EXPECT_NEAR(d.grad()[0][0][6][1].item<double>(), -1.0 / ((6 - 1.5) / 8 * 24), 1e-12);
  EXPECT_NEAR(d.grad()[0][0][5][2].item<double>(), -1.0 / ((5 - 1.5) / 8 * 24), 1e-12);
  EXPECT_EQ(d.grad()[0][0][4][3].item<double>(), 0.0);
  EXPECT_EQ(d.grad()[0][0][1][0].item<double>(), 0.0);
  EXPECT_EQ(d.grad()[0][0][7][0].item<double>(), 0.0);  // on the road
}

TEST(GroundPrior, TheBoundFollowsTheFittedHeightNotAKnownOne) {
  // The same road at any scale (a monocular network's unknown one) gives the same penalty.
  auto near = road_disparity(), far = road_disparity() * 3.0;
  near[0][0][6][1] = 0.0;
  far[0][0][6][1] = 0.0;
  EXPECT_NEAR(geo::ground_prior(near, camera()).item<double>(), geo::ground_prior(far, camera()).item<double>(), 1e-12);
}

TEST(GroundPrior, ThingsInFrontOfTheRoadDoNotMoveItsHeight) {
  // A car covering 3 of the 4 columns of row 7 and 2 of row 6 (less than half of the lower rows
  // 4..7) at twice the road's disparity: the median height stays the road's, nothing is penalised.
  auto d = road_disparity();
  for (int64_t u = 0; u < 3; ++u) d[0][0][7][u] = 2.0 * (7 - 1.5) / 8;
  for (int64_t u = 0; u < 2; ++u) d[0][0][6][u] = 2.0 * (6 - 1.5) / 8;
  d[0][0][3][0] = 0.0;  // one pixel beyond the road, whose bound would move with the height
  EXPECT_NEAR(geo::ground_prior(d, camera()).item<double>(), 0.95 / 24.0, 1e-12);
}

TEST(GroundPrior, AUniformDepthMapIsTaughtTheRoadBelowItsMedianRow) {
  // A network that sees no road yet: depth 1 everywhere. Heights (v - 1.5)/4 over rows 4..7 have
  // the median (lower middle) 0.875 (row 5): rows 6 and 7 then bound the disparity at 1.286 and
  // 1.571 (> 1), rows 2..5 not (their road is beyond depth 1).
  const auto d = torch::ones({1, 1, kH, kW}, torch::kFloat64);
  const double h = (5 - 1.5) / 4;
  const double expected = 4 * ((0.95 - h / ((6 - 1.5) / 4)) + (0.95 - h / ((7 - 1.5) / 4))) / 24.0;
  EXPECT_NEAR(geo::ground_prior(d, camera()).item<double>(), expected, 1e-12);
}

TEST(GroundPrior, AnImageWithoutRoadRowsAddsNothingAndStaysFinite) {
  // The principal point at the bottom: no row lies below the horizon.
  auto K = camera();
  K[0][1][2] = 8.0;
  auto d = road_disparity().requires_grad_(true);
  const auto loss = geo::ground_prior(d, K);
  EXPECT_EQ(loss.item<double>(), 0.0);
  loss.backward();
  EXPECT_TRUE(d.grad().isfinite().all().item<bool>());
  EXPECT_EQ(d.grad().abs().sum().item<double>(), 0.0);
}

TEST(GroundPrior, WrongShapesAreNamed) {
  EXPECT_THROW(geo::ground_prior(torch::ones({1, 2, kH, kW}), camera()), c10::Error);
  EXPECT_THROW(geo::ground_prior(torch::ones({2, 1, kH, kW}), camera()), c10::Error);
}

}  // namespace
