// Frames of the user's own footage: frame-rate subsampling, static frames, validation blocks, natural
// order and the clip's camera (data/video/frame_selection.h, data/video/clip_camera.h).
#include "data/video/clip_camera.h"
#include "data/video/frame_selection.h"

#include <gtest/gtest.h>

#include "test_util.h"

#include <algorithm>
#include <numeric>

namespace {

using geo::split_clip;

TEST(FrameSelection, StrideFromFrameRates) {
  EXPECT_EQ(geo::frame_rate_stride(30, 10), 3);
  EXPECT_EQ(geo::frame_rate_stride(60, 10), 6);
  EXPECT_EQ(geo::frame_rate_stride(29.97, 10), 3);
  EXPECT_EQ(geo::frame_rate_stride(25, 10), 3);  // 2.5 rounds away from zero
  EXPECT_EQ(geo::frame_rate_stride(10, 10), 1);
  EXPECT_EQ(geo::frame_rate_stride(5, 10), 1);  // slower than the target: every frame
  EXPECT_EQ(geo::frame_rate_stride(0, 10), 1);  // unknown source rate
  EXPECT_EQ(geo::frame_rate_stride(30, 0), 1);  // fps 0: every frame
}

TEST(FrameSelection, ChangedFractionCountsPixelsAboveTheNoiseLevel) {
  const auto a = torch::zeros({4, 4});
  auto b = a.clone();
  b[0][0] = 0.1;   // changed
  b[1][1] = -0.1;  // changed
  b[2][2] = 0.01;  // below 4/255: noise
  b[3][3] = 0.02;  // above 4/255 = 0.0157
  EXPECT_DOUBLE_EQ(geo::changed_fraction(a, b), 3.0 / 16.0);
  EXPECT_DOUBLE_EQ(geo::changed_fraction(a, a), 0.0);
  // The thumbnail is a grey area average about 32 rows high.
  const auto frame = torch::rand({3, 128, 416});
  const auto t = geo::motion_thumbnail(frame);
  EXPECT_EQ(t.sizes(), (std::vector<int64_t>{32, 104}));
  EXPECT_NEAR(t.mean().item<double>(), frame.mean().item<double>(), 1e-5);
}

TEST(FrameSelection, StaticFramesAreLeftOutAndTheNextMovingFrameFollows) {
  // Frames 0..9: the camera waits from frame 3 to 6 (they repeat frame 2), then moves again.
  std::vector<torch::Tensor> thumbs;
  for (int i = 0; i < 10; ++i) {
    const int content = (i >= 3 && i <= 6) ? 2 : i;
    thumbs.push_back(torch::full({8, 8}, 0.05 * content));
  }
  geo::FrameSelector every(1, 0.05);
  for (int i = 0; i < 10; ++i) every.offer(i, thumbs[static_cast<size_t>(i)]);
  EXPECT_EQ(every.kept(), (std::vector<int64_t>{0, 1, 2, 7, 8, 9}));
  EXPECT_EQ(every.skipped_static(), 4);
  EXPECT_EQ(every.skipped_by_rate(), 0);
  EXPECT_EQ(every.decoded(), 10);
  EXPECT_DOUBLE_EQ(every.largest_change(), 1.0);
  // Every 2nd frame for the rate: 0 2 (4 and 6 static: equal to 2) 8.
  geo::FrameSelector half(2, 0.05);
  for (int i = 0; i < 10; ++i) half.offer(i, half.wants(i) ? thumbs[static_cast<size_t>(i)] : torch::Tensor());
  EXPECT_EQ(half.kept(), (std::vector<int64_t>{0, 2, 8}));
  EXPECT_EQ(half.skipped_by_rate(), 5);
  EXPECT_EQ(half.skipped_static(), 2);
  // Threshold 0 keeps every frame looked at.
  geo::FrameSelector all(1, 0.0);
  for (int i = 0; i < 10; ++i) all.offer(i, thumbs[static_cast<size_t>(i)]);
  EXPECT_EQ(all.kept().size(), 10u);
}

TEST(FrameSelection, ValidationBlocksNeverNeighbourTrainingFrames) {
  // 100 frames, 10%, blocks of up to 100: one block, the last 10 frames; frame 89 left out.
  auto r = split_clip(100, 0.1, 100, 3);
  ASSERT_EQ(r.val.size(), 1u);
  EXPECT_EQ(r.val[0].front(), 90);
  EXPECT_EQ(r.val[0].back(), 99);
  ASSERT_EQ(r.train.size(), 1u);
  EXPECT_EQ(r.train[0].front(), 0);
  EXPECT_EQ(r.train[0].back(), 88);
  EXPECT_EQ(r.edge_dropped, 1);
  EXPECT_EQ(geo::snippet_targets(r.train, 3).size(), 87u);  // targets 1..87
  EXPECT_EQ(geo::snippet_targets(r.val, 3).size(), 8u);     // targets 91..98
  // 1000 frames in blocks of 50: 100 validation frames in 2 blocks, ending at 500 and 1000.
  r = split_clip(1000, 0.1, 50, 5);
  ASSERT_EQ(r.val.size(), 2u);
  EXPECT_EQ(r.val[0].front(), 450);
  EXPECT_EQ(r.val[0].back(), 499);
  EXPECT_EQ(r.val[1].front(), 950);
  ASSERT_EQ(r.train.size(), 2u);
  EXPECT_EQ(r.train[0].back(), 447);   // 448, 449 left out (5-frame snippets: 2 each side)
  EXPECT_EQ(r.train[1].front(), 502);  // 500, 501 left out
  EXPECT_EQ(r.train[1].back(), 947);
  EXPECT_EQ(r.edge_dropped, 6);
  // No training frame within seq_length/2 of a validation frame, every frame used once at most.
  std::vector<int> seen(1000, 0);
  for (const auto& run : r.val) {
    for (auto p : run) seen[static_cast<size_t>(p)] = 2;
  }
  for (const auto& run : r.train) {
    for (auto p : run) {
      ASSERT_EQ(seen[static_cast<size_t>(p)], 0);
      seen[static_cast<size_t>(p)] = 1;
      for (int d = -2; d <= 2; ++d) {
        if (p + d >= 0 && p + d < 1000) {
          EXPECT_NE(seen[static_cast<size_t>(p + d)], 2) << p;
        }
      }
    }
  }
  // Too short for one validation snippet: everything trains.
  r = split_clip(20, 0.1, 100, 3);
  EXPECT_TRUE(r.val.empty());
  ASSERT_EQ(r.train.size(), 1u);
  EXPECT_EQ(r.train[0].size(), 20u);
  EXPECT_EQ(split_clip(50, 0.0, 100, 3).val.size(), 0u);
}

TEST(FrameSelection, NaturalOrderComparesNumbersAsNumbers) {
  std::vector<std::string> names{"frame10.png", "frame2.png", "frame1.png", "b.png", "a.png", "frame002.png"};
  std::sort(names.begin(), names.end(), geo::natural_less);
  EXPECT_EQ(names,
            (std::vector<std::string>{"a.png", "b.png", "frame1.png", "frame002.png", "frame2.png", "frame10.png"}));
  EXPECT_TRUE(geo::natural_less("img_9.jpg", "img_10.jpg"));
  EXPECT_FALSE(geo::natural_less("img_10.jpg", "img_9.jpg"));
  EXPECT_FALSE(geo::natural_less("x", "x"));
  EXPECT_TRUE(geo::natural_less("0000000009.png", "0000000010.png"));
}

geo::CameraConfig camera_with(std::vector<double> intrinsics) {
  geo::CameraConfig c;
  c.intrinsics = std::move(intrinsics);
  return c;
}

std::string error_of(const geo::CameraConfig& c, int64_t w, int64_t h) {
  try {
    geo::clip_camera(c, w, h, "clip.mp4");
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

TEST(ClipCamera, FromIntrinsicsFieldOfViewOrCalibrationFile) {
  auto K = geo::clip_camera(camera_with({700, 710, 640, 360}), 1280, 720, "clip.mp4");
  EXPECT_DOUBLE_EQ(K[0][0].item<double>(), 700);
  EXPECT_DOUBLE_EQ(K[1][1].item<double>(), 710);
  EXPECT_DOUBLE_EQ(K[0][2].item<double>(), 640);
  EXPECT_DOUBLE_EQ(K[1][2].item<double>(), 360);
  // 90 degrees across 1000 px: f = 500 / tan(45 deg) = 500, principal point at the centre pixel.
  geo::CameraConfig fov;
  fov.fov_deg = 90;
  K = geo::clip_camera(fov, 1000, 500, "clip.mp4");
  EXPECT_NEAR(K[0][0].item<double>(), 500, 1e-9);
  EXPECT_NEAR(K[1][1].item<double>(), 500, 1e-9);
  EXPECT_DOUBLE_EQ(K[0][2].item<double>(), 499.5);
  EXPECT_DOUBLE_EQ(K[1][2].item<double>(), 249.5);
  // KITTI raw calibration: P_rect_02 at S_rect_02; frames of half the size scale it.
  const auto dir = geo::test::fresh_dir("clip_camera");
  geo::test::write_text(dir + "/calib_cam_to_cam.txt",
                        "calib_time: 09-Jan-2012 13:57:47\nS_rect_02: 1.242000e+03 3.750000e+02\n"
                        "P_rect_02: 7.215377e+02 0.000000e+00 6.095593e+02 4.485728e+01 0.000000e+00 7.215377e+02 "
                        "1.728540e+02 2.163791e-01 0.000000e+00 0.000000e+00 1.000000e+00 2.745884e-03\n");
  geo::CameraConfig calib;
  calib.calib_file = dir + "/calib_cam_to_cam.txt";
  K = geo::clip_camera(calib, 1242, 375, "frames/");
  EXPECT_DOUBLE_EQ(K[0][0].item<double>(), 721.5377);
  EXPECT_DOUBLE_EQ(K[1][2].item<double>(), 172.854);
  K = geo::clip_camera(calib, 621, 375, "frames/");  // resized in x only
  EXPECT_DOUBLE_EQ(K[0][0].item<double>(), 721.5377 / 2);
  EXPECT_DOUBLE_EQ(K[0][2].item<double>(), 609.5593 / 2);
  EXPECT_DOUBLE_EQ(K[1][1].item<double>(), 721.5377);
}

TEST(ClipCamera, AbsurdOrMissingCamerasNameTheKeyAndValue) {
  EXPECT_NE(error_of(camera_with({0, 700, 640, 360}), 1280, 720).find("data.camera.intrinsics: focal lengths fx = 0"),
            std::string::npos);
  EXPECT_NE(error_of(camera_with({-5, 700, 640, 360}), 1280, 720).find("fx = -5"), std::string::npos);
  const auto outside = error_of(camera_with({700, 700, 5000, 360}), 1280, 720);
  EXPECT_NE(outside.find("principal point (5000, 360) lies outside the 1280x720 frame (give it in pixels of the "
                         "original frames) ('clip.mp4')"),
            std::string::npos)
      << outside;
  const auto none = error_of(geo::CameraConfig{}, 1280, 720);
  EXPECT_NE(none.find("data.camera: no camera given for 'clip.mp4'"), std::string::npos) << none;
  const auto dir = geo::test::fresh_dir("clip_camera_bad");
  geo::test::write_text(dir + "/calib.txt", "Tr: 1 0 0 0 0 1 0 0 0 0 1 0\n");
  geo::CameraConfig calib;
  calib.calib_file = dir + "/calib.txt";
  EXPECT_NE(error_of(calib, 1242, 375).find("has neither P_rect_02"), std::string::npos);
  calib.calib_file = dir + "/missing.txt";
  EXPECT_NE(error_of(calib, 1242, 375).find("missing.txt"), std::string::npos);
}

}  // namespace
