// Image, flow and depth PNGs: exact round trips at the formats' resolution and clear errors.
#include "data/image_io.h"
#include "data/cv_tensor.h"
#include "core/zip_check.h"
#include "geometry/warp.h"

#include <gtest/gtest.h>

#include "test_util.h"

namespace geo {
namespace {

TEST(ImageIo, ImageRoundTripIsExactIn8Bit) {
  const auto dir = test::fresh_dir("img");
  const auto img = torch::randint(0, 256, {3, 5, 7}, torch::kUInt8).to(torch::kFloat32) / 255;
  write_image(dir + "/a.png", img);
  EXPECT_TRUE(torch::allclose(read_image(dir + "/a.png"), img, 0, 1e-6));
  const auto small = read_image_resized(dir + "/a.png", 3, 4);
  EXPECT_EQ(small.sizes(), (torch::IntArrayRef{3, 3, 4}));
}

// geo_infer's frames: 8-bit images stay uint8 (the values resized_mat_to_tensor scales to [0,1]),
// 16-bit ones are float; both resized alike.
TEST(ImageIo, FramesStayEightBitWhereTheImageIs) {
  const auto bgr8 = cv::Mat(6, 10, CV_8UC3);
  cv::randu(bgr8, 0, 256);
  const auto frame = resized_mat_to_frame(bgr8, 3, 5, "a");
  ASSERT_EQ(frame.scalar_type(), torch::kUInt8);
  EXPECT_EQ(frame.sizes(), (torch::IntArrayRef{3, 3, 5}));
  EXPECT_TRUE(torch::allclose(frame.to(torch::kFloat32) / 255, resized_mat_to_tensor(bgr8, 3, 5, "a"), 0, 1e-6));
  // At its own size: the bytes as they are, red first (OpenCV's channel 2).
  const auto same = resized_mat_to_frame(bgr8, 6, 10, "a");
  EXPECT_EQ(same[0][4][7].item<int>(), bgr8.at<cv::Vec3b>(4, 7)[2]);
  EXPECT_EQ(same[2][4][7].item<int>(), bgr8.at<cv::Vec3b>(4, 7)[0]);
  cv::Mat bgr16;
  bgr8.convertTo(bgr16, CV_16UC3, 257);
  const auto deep = resized_mat_to_frame(bgr16, 3, 5, "b");
  ASSERT_EQ(deep.scalar_type(), torch::kFloat32);
  EXPECT_TRUE(torch::allclose(deep, resized_mat_to_tensor(bgr16, 3, 5, "b"), 0, 0));
}

TEST(ImageIo, FlowPngRoundTripAtOneSixtyFourthPixel) {
  const auto dir = test::fresh_dir("flow");
  const auto flow = torch::randint(-20000, 20000, {2, 4, 6}).to(torch::kFloat32) / 64;
  auto valid = torch::ones({1, 4, 6});
  valid[0][1][2] = 0;
  write_flow_png(dir + "/f.png", flow, valid);
  const auto back = read_flow_png(dir + "/f.png");
  EXPECT_TRUE(torch::equal(back.valid, valid));
  EXPECT_TRUE(torch::equal(back.flow * valid, flow * valid));
}

TEST(ImageIo, DepthPngRoundTripAtOneTwoFiftySixthMetre) {
  const auto dir = test::fresh_dir("depth");
  const auto depth = torch::randint(0, 65535, {1, 4, 6}).to(torch::kFloat32) / 256;
  write_depth_png(dir + "/d.png", depth);
  EXPECT_TRUE(torch::equal(read_depth_png(dir + "/d.png"), depth));
}

TEST(ImageIo, BadFilesAreNamed) {
  const auto dir = test::fresh_dir("bad");
  GEO_EXPECT_THROW_WITH(read_image(dir + "/missing.png"), "missing.png", "not found");
  test::write_text(dir + "/corrupt.png", "this is not a png");
  GEO_EXPECT_THROW_WITH(read_image(dir + "/corrupt.png"), "corrupt.png", "cannot decode");
  write_image(dir + "/rgb.png", torch::zeros({3, 4, 4}));
  GEO_EXPECT_THROW_WITH(read_flow_png(dir + "/rgb.png"), "rgb.png", "16-bit");
  GEO_EXPECT_THROW_WITH(read_depth_png(dir + "/rgb.png"), "rgb.png", "got 3 channel(s) of 8-bit");
  // A 16-bit grey PNG (a depth map) given as flow: the message says what it is.
  write_depth_png(dir + "/grey16.png", torch::ones({1, 4, 4}));
  GEO_EXPECT_THROW_WITH(read_flow_png(dir + "/grey16.png"), "grey16.png", "got 1 channel(s) of 16-bit");
  // A header claiming 100000 x 100000 pixels (its CRC made valid): OpenCV's size assertion becomes
  // an error naming the file.
  std::string png = test::read_file(dir + "/rgb.png");
  ASSERT_EQ(png.substr(12, 4), "IHDR");
  for (int k : {16, 20}) {  // width, height: big-endian 100000 = 0x000186A0
    png[k] = 0, png[k + 1] = 0x01, png[k + 2] = static_cast<char>(0x86), png[k + 3] = static_cast<char>(0xA0);
  }
  const uint32_t crc = crc32(png.data() + 12, 17);
  for (int k = 0; k < 4; ++k) png[29 + k] = static_cast<char>((crc >> (24 - 8 * k)) & 0xFF);
  test::write_text(dir + "/huge.png", png);
  GEO_EXPECT_THROW_WITH(read_image(dir + "/huge.png"), "huge.png", "cannot decode");
}

TEST(KittiFlowSamples, Flow2012GroundTruthWarpHalvesTheError) {
  const auto root = test::kitti_samples();
  if (root.empty()) GTEST_SKIP() << "../shared/kitti_samples not present";
  const std::string d = root + "/flow2012/training";
  const auto a = read_image(d + "/image_0/000157_10.png").unsqueeze(0);
  const auto b = read_image(d + "/image_0/000157_11.png").unsqueeze(0);
  const auto gt = read_flow_png(d + "/flow_noc/000157_10.png");
  const auto valid = gt.valid.unsqueeze(0);
  const auto warped = warp(b, gt.flow.unsqueeze(0), OutOfView::kBorder).image;
  auto err = [&](const torch::Tensor& x) {
    return ((x - a).abs().mean(1, true) * valid).sum().item<double>() * 255 / valid.sum().item<double>();
  };
  const double before = err(b), after = err(warped);
  EXPECT_GT(before, 2 * after) << "before " << before << ", after " << after;
  // The flow PNG's conventions (u before v, forward, pixels): the ground truth beats its negation,
  // its components swapped and itself one pixel off in either direction.
  const auto f = gt.flow.unsqueeze(0);
  auto err_with = [&](const torch::Tensor& flow) { return err(warp(b, flow, OutOfView::kBorder).image); };
  EXPECT_LT(after, err_with(-f));
  EXPECT_LT(after, err_with(f.flip(1)));
  for (const auto& shift : {torch::tensor({1.f, 0.f}), torch::tensor({0.f, 1.f})})
    EXPECT_LT(after, err_with(f + shift.view({1, 2, 1, 1})));
}

}  // namespace
}  // namespace geo
