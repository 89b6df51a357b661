// geo_infer's outputs for people (data/visual_outputs.h): Motion-JPEG videos written in one piece,
// and the trajectory's top view with its ground truth.
#include "data/visual_outputs.h"

#include <gtest/gtest.h>
#include <opencv2/videoio.hpp>

#include "test_util.h"

#include <filesystem>

namespace geo {
namespace {

namespace fs = std::filesystem;

TEST(VideoWriter, FramesRoundTripAndAFailedRunLeavesNoFile) {
  const auto dir = test::fresh_dir("video_writer");
  {
    VideoWriter w(dir + "/a.avi", 10);
    for (int i = 0; i < 3; ++i) w.write(torch::full({3, 32, 48}, 0.25 * i));
    EXPECT_FALSE(fs::exists(dir + "/a.avi"));  // only under the temporary name until closed
    w.close();
    EXPECT_EQ(w.frames(), 3);
  }
  EXPECT_TRUE(fs::exists(dir + "/a.avi"));
  EXPECT_FALSE(fs::exists(dir + "/a.avi.tmp.avi"));
  cv::VideoCapture cap(dir + "/a.avi");
  ASSERT_TRUE(cap.isOpened());
  cv::Mat m;
  int n = 0;
  while (cap.read(m)) {
    EXPECT_EQ(m.cols, 48);
    EXPECT_EQ(m.rows, 32);
    EXPECT_NEAR(m.at<cv::Vec3b>(16, 24)[1], 255 * 0.25 * n, 3) << "frame " << n;  // JPEG, flat grey
    ++n;
  }
  EXPECT_EQ(n, 3);

  {
    VideoWriter w(dir + "/b.avi", 10);
    w.write(torch::zeros({3, 32, 48}));
    GEO_EXPECT_THROW_WITH(w.write(torch::zeros({3, 16, 48})), dir + "/b.avi", "frame 1 is 48x16", "first was 48x32");
  }  // not closed: nothing is left
  EXPECT_FALSE(fs::exists(dir + "/b.avi"));
  EXPECT_FALSE(fs::exists(dir + "/b.avi.tmp.avi"));
  VideoWriter empty(dir + "/c.avi", 10);
  GEO_EXPECT_THROW_WITH(empty.close(), dir + "/c.avi", "no frames");
  GEO_EXPECT_THROW_WITH(VideoWriter(dir + "/d.avi", 0), "frame rate must be positive");
}

// A straight drive along z (x = 0) and a ground truth 2 units to its right, z from 0 to 10: the
// larger extent (z, 10) fills 200 - 2 x 16 pixels (16.8 px per unit), x is centred. So z = 5 is
// row 200 - (16 + 5 x 16.8) = 100, the estimate's column 16 + (168 - 2 x 16.8) / 2 = 83.2 and the
// truth's 83.2 + 33.6 = 116.8.
TEST(TrajectoryPlot, DrawsEstimateAndTruthToScaleFromAbove) {
  auto poses = torch::eye(4, torch::kFloat64).repeat({11, 1, 1});
  for (int i = 0; i <= 10; ++i) poses[i][2][3] = i;
  auto truth = poses.clone();
  truth.select(2, 3).select(1, 0).fill_(2.0);
  const auto img = trajectory_plot(poses, truth, 200);
  ASSERT_EQ(img.sizes(), (std::vector<int64_t>{3, 200, 200}));
  auto rgb = [&](int row, int col) { return img.index({torch::indexing::Slice(), row, col}); };
  EXPECT_TRUE(torch::allclose(rgb(100, 83), torch::tensor({1.0f, 120 / 255.f, 0.0f}), 0, 0.15)) << rgb(100, 83);
  EXPECT_TRUE(torch::allclose(rgb(100, 117), torch::zeros({3}), 0, 0.15)) << rgb(100, 117);
  EXPECT_TRUE(torch::allclose(rgb(100, 100), torch::ones({3}), 0, 0.15)) << rgb(100, 100);  // between: paper or grid
  // Alone, the estimate is centred.
  const auto alone = trajectory_plot(poses, {}, 200);
  EXPECT_TRUE(torch::allclose(alone.index({torch::indexing::Slice(), 100, 100}),
                              torch::tensor({1.0f, 120 / 255.f, 0.0f}), 0, 0.15));
  GEO_EXPECT_THROW_WITH(trajectory_plot(torch::zeros({3, 3, 4})), "poses");
}

}  // namespace
}  // namespace geo
