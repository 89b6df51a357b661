// Coloured point clouds (data/point_cloud.h): every kept pixel back-projected through K, in a PLY
// file that other tools read.
#include "data/point_cloud.h"

#include <gtest/gtest.h>

#include "test_util.h"

#include <cstring>

namespace geo {
namespace {

// depth [[2, 0], [8, 4]], K = [[2, 0, 0.5], [0, 2, 0.5], [0, 0, 1]]: pixel (u, v) at depth d is
// ((u - 0.5) d / 2, (v - 0.5) d / 2, d). Pixel (1, 0) has no depth; max_depth 5 drops (0, 1).
TEST(PointCloud, PlyHoldsTheBackProjectedColouredPixels) {
  const auto dir = test::fresh_dir("point_cloud");
  const auto depth = torch::tensor({2.f, 0.f, 8.f, 4.f}).view({1, 2, 2});
  const auto rgb = torch::stack({torch::full({2, 2}, 1.0), torch::full({2, 2}, 0.5), torch::zeros({2, 2})});
  const auto K = torch::tensor({2.f, 0.f, 0.5f, 0.f, 2.f, 0.5f, 0.f, 0.f, 1.f}).view({3, 3});
  ASSERT_EQ(write_point_cloud_ply(dir + "/a.ply", depth, rgb, K, 5.0), 2);
  const std::string bytes = test::read_file(dir + "/a.ply");
  const auto end = bytes.find("end_header\n");
  ASSERT_NE(end, std::string::npos);
  const std::string header = bytes.substr(0, end);
  EXPECT_NE(header.find("format binary_little_endian 1.0"), std::string::npos);
  EXPECT_NE(header.find("element vertex 2\n"), std::string::npos);
  const char* body = bytes.data() + end + 11;
  ASSERT_EQ(bytes.size(), end + 11 + 2 * 15);
  const float expected[2][3] = {{-0.5f, -0.5f, 2.f}, {1.f, 1.f, 4.f}};
  for (int p = 0; p < 2; ++p) {
    float xyz[3];
    std::memcpy(xyz, body + 15 * p, 12);
    for (int k = 0; k < 3; ++k) EXPECT_FLOAT_EQ(xyz[k], expected[p][k]) << "point " << p << " coordinate " << k;
    EXPECT_EQ(static_cast<uint8_t>(body[15 * p + 12]), 255);
    EXPECT_EQ(static_cast<uint8_t>(body[15 * p + 13]), 128);
    EXPECT_EQ(static_cast<uint8_t>(body[15 * p + 14]), 0);
  }
  EXPECT_EQ(write_point_cloud_ply(dir + "/b.ply", depth[0], rgb, K), 3);  // [H,W] depth, no limit
  // uint8 colours (geo_infer's 8-bit frames) are the bytes as they are: the same file.
  const auto rgb8 =
      torch::stack({torch::full({2, 2}, 255), torch::full({2, 2}, 128), torch::zeros({2, 2})}).to(torch::kUInt8);
  ASSERT_EQ(write_point_cloud_ply(dir + "/a8.ply", depth, rgb8, K, 5.0), 2);
  EXPECT_EQ(test::read_file(dir + "/a8.ply"), bytes);
  GEO_EXPECT_THROW_WITH(write_point_cloud_ply(dir + "/c.ply", depth, rgb.slice(1, 0, 1), K), "rgb");
}

}  // namespace
}  // namespace geo
