#include "data/velodyne_depth.h"

#include "core/tensor_checks.h"

#include <cmath>

namespace geo {

torch::Tensor velodyne_depth(const torch::Tensor& points, const torch::Tensor& img_from_velo,
                             int64_t height, int64_t width, VelodyneDepthOptions options) {
  check_shape(points, "velodyne points", {-1, 4});
  check_shape(img_from_velo, "img_from_velo", {3, 4});
  auto pts = points.to(torch::kFloat64).contiguous();
  auto P = img_from_velo.to(torch::kFloat64).contiguous();
  auto depth = torch::zeros({height, width}, torch::kFloat32);
  auto d = depth.accessor<float, 2>();
  auto p = pts.accessor<double, 2>();
  auto m = P.accessor<double, 2>();
  const double offset = options.matlab_offset ? 1.0 : 0.0;
  for (int64_t i = 0; i < pts.size(0); ++i) {
    const double x = p[i][0], y = p[i][1], z = p[i][2];
    if (x < 0) continue;  // behind the scanner (reference code)
    double img[3];
    for (int r = 0; r < 3; ++r) img[r] = m[r][0] * x + m[r][1] * y + m[r][2] * z + m[r][3];
    if (img[2] <= 0) continue;
    const int64_t u = static_cast<int64_t>(std::round(img[0] / img[2]) - offset);
    const int64_t v = static_cast<int64_t>(std::round(img[1] / img[2]) - offset);
    if (u < 0 || v < 0 || u >= width || v >= height) continue;
    const float value = static_cast<float>(options.depth_is_velo_x ? x : img[2]);
    float& cell = d[v][u];
    if (cell == 0.f || value < cell) cell = value;  // nearest point wins
  }
  return depth;
}

}  // namespace geo
