// The road plane and the camera-height scale on synthetic depth of a known plane: exact heights
// (with obstacles and holes as outliers, at any scale, with the camera pitched), failures reported.
#include "geometry/road_plane.h"

#include <gtest/gtest.h>

#include <cmath>

namespace geo {
namespace {

constexpr int64_t kH = 48, kW = 160;
const double kFx = 120, kFy = 120, kCx = 80, kCy = 20;

torch::Tensor K() { return torch::tensor({kFx, 0.0, kCx, 0.0, kFy, kCy, 0.0, 0.0, 1.0}, torch::kFloat64).view({3, 3}); }

// Depth of the plane n.X = h seen through K (rays that miss it, or hit it behind the camera, see a
// wall at `far`): z = h / (n . K^-1 [u v 1]).
torch::Tensor plane_depth(const double n[3], double h, double far = 80) {
  auto depth = torch::full({kH, kW}, far, torch::kFloat64);
  auto a = depth.accessor<double, 2>();
  for (int64_t v = 0; v < kH; ++v)
    for (int64_t u = 0; u < kW; ++u) {
      const double ray = n[0] * (u - kCx) / kFx + n[1] * (v - kCy) / kFy + n[2];
      if (ray > 1e-9 && h / ray < far) a[v][u] = h / ray;
    }
  return depth;
}

TEST(RoadPlane, KnownPlaneGivesItsExactHeightDespiteObstaclesAndHoles) {
  const double down[3] = {0, 1, 0};
  auto depth = plane_depth(down, 1.65);
  // Obstacles: a car's back at half the road's depth in a block of the lower image (its points
  // stand 0.8 m above the road), holes (0 and NaN) elsewhere.
  depth.slice(0, 34, 44).slice(1, 20, 60).mul_(0.5);
  depth.slice(0, 40, 48).slice(1, 100, 110).zero_();
  depth[47][150] = std::nan("");
  const auto plane = fit_road_plane(depth, K());
  ASSERT_TRUE(plane.found) << plane.why;
  EXPECT_NEAR(plane.height, 1.65, 1e-9);
  EXPECT_NEAR(plane.normal[1], 1.0, 1e-12);
  EXPECT_LT(plane.inliers, plane.points);  // the car's points are out
  EXPECT_NEAR(camera_height_scale(plane, 1.65), 1.0, 1e-9);
  // Depth up to a factor: the scale that takes it back to metres.
  const auto scaled = fit_road_plane(depth * 0.25, K());
  ASSERT_TRUE(scaled.found);
  EXPECT_NEAR(scaled.height, 1.65 * 0.25, 1e-9);
  EXPECT_NEAR(camera_height_scale(scaled, 1.65), 4.0, 1e-8);
}

TEST(RoadPlane, APitchedCameraSeesTheSameHeight) {
  const double pitch = 4.0 * M_PI / 180;  // the road's normal 4 degrees off the camera's y axis
  const double n[3] = {0, std::cos(pitch), std::sin(pitch)};
  RoadPlaneOptions free;
  free.level_camera = false;  // the normal fitted as well
  const auto plane = fit_road_plane(plane_depth(n, 1.73), K(), free);
  ASSERT_TRUE(plane.found) << plane.why;
  EXPECT_NEAR(plane.height, 1.73, 1e-9);
  EXPECT_NEAR(plane.normal[2], std::sin(pitch), 1e-9);
  // The same obstacles and holes as above with the normal fitted: still the exact height.
  const double down[3] = {0, 1, 0};
  auto depth = plane_depth(down, 1.65);
  depth.slice(0, 34, 44).slice(1, 20, 60).mul_(0.5);
  depth.slice(0, 40, 48).slice(1, 100, 110).zero_();
  const auto level = fit_road_plane(depth, K(), free);
  ASSERT_TRUE(level.found) << level.why;
  EXPECT_NEAR(level.height, 1.65, 1e-9);
}

TEST(RoadPlane, NoRoadIsReportedNotGuessed) {
  // A wall filling the image (constant depth: a fronto-parallel plane, 90 degrees from a road): no
  // level plane holds 20% of its points, and no plane within 20 degrees of horizontal fits it.
  const auto wall = fit_road_plane(torch::full({kH, kW}, 5.0, torch::kFloat64), K());
  EXPECT_FALSE(wall.found);
  EXPECT_NE(wall.why.find("lie on one level road plane"), std::string::npos) << wall.why;
  EXPECT_EQ(camera_height_scale(wall, 1.65), 0.0);
  RoadPlaneOptions free;
  free.level_camera = false;
  const auto tilted = fit_road_plane(torch::full({kH, kW}, 5.0, torch::kFloat64), K(), free);
  EXPECT_FALSE(tilted.found);
  EXPECT_NE(tilted.why.find("degrees"), std::string::npos) << tilted.why;
  const auto empty = fit_road_plane(torch::zeros({kH, kW}), K());
  EXPECT_FALSE(empty.found);
  EXPECT_NE(empty.why.find("fewer than 3 valid depths"), std::string::npos) << empty.why;
}

TEST(RoadPlane, SmoothedScalesAreWindowMediansThatBridgeFailures) {
  // Window of radius 1: medians of {2,4}, {2,4,100}, {4,100}, {100, 6}... 0 = not found, skipped.
  const auto s = smooth_scales({2, 4, 100, 0, 6}, 1);
  ASSERT_EQ(s.size(), 5u);
  EXPECT_DOUBLE_EQ(s[0], 3);
  EXPECT_DOUBLE_EQ(s[1], 4);
  EXPECT_DOUBLE_EQ(s[2], 52);
  EXPECT_DOUBLE_EQ(s[3], 53);
  EXPECT_DOUBLE_EQ(s[4], 6);
  EXPECT_EQ(smooth_scales({0, 0}, 3), (std::vector<double>{0, 0}));
}

}  // namespace
}  // namespace geo
