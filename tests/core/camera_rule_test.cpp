#include "core/camera_rule.h"

#include <gtest/gtest.h>

#include <cmath>

namespace geo {
namespace {

bool has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

TEST(CameraRule, PlausibleCamerasPassIncludingTheFramesEdges) {
  EXPECT_EQ(camera_problem(721.5377, 721.5377, 609.5593, 172.854, 1242, 375), "");  // KITTI's P_rect_02
  EXPECT_EQ(camera_problem(1, 99999, 0, 0, 1242, 375), "");
  EXPECT_EQ(camera_problem(700, 700, 1242, 375, 1242, 375), "");
  EXPECT_EQ(camera_problem(700, 700, -5e4, 9e4), "");  // no frame size: within 1e5 px
}

TEST(CameraRule, FocalLengthsOutOfRangeAreNamed) {
  const auto zero = camera_problem(0, 700, 640, 360, 1280, 720);
  EXPECT_TRUE(has(zero, "focal lengths fx = 0, fy = 700 are not plausible")) << zero;
  // Finite and positive but far below a pixel: normalised intrinsics, or a typo.
  const auto tiny = camera_problem(1e-300, 700, 640, 360);
  EXPECT_TRUE(has(tiny, "fx = 1e-300") && has(tiny, ">= 1 and < 1e5")) << tiny;
  const auto normalised = camera_problem(0.58, 1.92, 0.5, 0.5, 1280, 720);
  EXPECT_TRUE(has(normalised, "fx = 0.58, fy = 1.92") && has(normalised, "normalised by the image size")) << normalised;
  EXPECT_TRUE(has(camera_problem(700, 1e5, 640, 360), "fy = 100000"));
  EXPECT_TRUE(has(camera_problem(700, std::nan(""), 640, 360), "fy = nan"));
}

TEST(CameraRule, PrincipalPointsOutsideTheFrameAreNamed) {
  EXPECT_EQ(camera_problem(100, 100, -500, 9000, 208, 64),
            "principal point (-500, 9000) lies outside the 208x64 frame (give it in pixels of the original frames)");
  EXPECT_TRUE(has(camera_problem(700, 700, 1242.5, 100, 1242, 375), "(1242.5, 100) lies outside the 1242x375 frame"));
  EXPECT_TRUE(has(camera_problem(700, 700, 600, -0.5, 1242, 375), "(600, -0.5) lies outside"));
  EXPECT_EQ(camera_problem(100, 100, 1e30, 0),
            "principal point cx = 1e+30, cy = 0 is not plausible (must be within 1e5 pixels)");
  EXPECT_TRUE(has(camera_problem(100, 100, 0, std::nan("")), "cy = nan"));
}

}  // namespace
}  // namespace geo
