// The trajectory chain: camera-to-world poses from next-from-this steps, hand-computed, and the
// per-step metric scales.
#include "geometry/trajectory.h"

#include <gtest/gtest.h>

#include "test_util.h"

namespace geo {
namespace {

torch::Tensor translation(double x, double y, double z) {
  auto T = torch::eye(4, torch::kFloat64);
  T[0][3] = x, T[1][3] = y, T[2][3] = z;
  return T;
}

// A camera that drives 1 forward per frame sees points 1 closer: next_from_this moves them by -1 in z.
TEST(Trajectory, StepsChainIntoCameraToWorldPoses) {
  TrajectoryChain chain;
  chain.add_step(translation(0, 0, -1));
  // Then a quarter turn to the left about y with no translation: next_from_this is R_y(+90deg)^T ...
  auto turn = torch::eye(4, torch::kFloat64);
  turn[0][0] = 0, turn[0][2] = -1, turn[2][0] = 1, turn[2][2] = 0;  // points: x' = -z, z' = x
  chain.add_step(turn);
  chain.add_step(translation(0, 0, -2).to(torch::kFloat32));  // float32 steps are taken as float64
  ASSERT_EQ(chain.steps(), 3u);
  const auto p = chain.poses();
  ASSERT_EQ(p.sizes(), (torch::IntArrayRef{4, 4, 4}));
  EXPECT_TRUE(torch::equal(p[0], torch::eye(4, torch::kFloat64)));
  EXPECT_TRUE(torch::allclose(p[1], translation(0, 0, 1)));
  // After the turn the camera's z axis is the world's x: 2 forward is x += 2 from (0, 0, 1).
  EXPECT_NEAR(p[3][0][3].item<double>(), 2.0, 1e-12);
  EXPECT_NEAR(p[3][2][3].item<double>(), 1.0, 1e-12);
  // Metric scales multiply each step's translation: 1 x 2 forward, then 2 x 3 along x.
  const auto m = chain.poses({2.0, 5.0, 3.0});
  EXPECT_NEAR(m[1][2][3].item<double>(), 2.0, 1e-12);
  EXPECT_NEAR(m[3][0][3].item<double>(), 6.0, 1e-12);
  EXPECT_NEAR(m[3][2][3].item<double>(), 2.0, 1e-12);
  EXPECT_THROW(chain.poses({1.0}), c10::Error);  // fewer scales than steps
}

TEST(Trajectory, MetricScalesAreSmoothedBridgedAndASequenceWithoutRoadIsNamed) {
  const auto none = [](size_t i) { return "frame " + std::to_string(i) + " has no road"; };
  // Frames without a road (0) take the median of their neighbours within 5 frames.
  EXPECT_EQ(metric_scales({2, 0, 4}, none), (std::vector<double>{3, 3, 3}));
  // Farther from any road, the nearest frame's smoothed scale (the earlier one on a tie): frames 0-5
  // see frame 0's 1.5 within 5 frames, 13-18 frame 18's 2.5; 6-9 are nearer frame 5 (9 a tie), 10-12
  // frame 13.
  std::vector<double> far(19, 0.0);
  far[0] = 1.5;
  far[18] = 2.5;
  std::vector<double> want(19, 1.5);
  for (size_t i = 10; i < 19; ++i) want[i] = 2.5;
  EXPECT_EQ(metric_scales(far, none), want);
  GEO_EXPECT_THROW_WITH(metric_scales(std::vector<double>(4, 0.0), none), "frame 0 has no road");
}

}  // namespace
}  // namespace geo
