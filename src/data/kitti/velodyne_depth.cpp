#include "data/kitti/velodyne_depth.h"

#include "core/tensor_checks.h"

#include <cmath>

namespace geo {

torch::Tensor velodyne_depth(const torch::Tensor& points, const torch::Tensor& img_from_velo, int64_t height,
                             int64_t width, VelodyneDepthOptions options) {
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
    if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) continue;  // counted by the caller
    if (x < 0) continue;                                                        // behind the scanner (reference code)
    double img[3];
    for (int r = 0; r < 3; ++r) img[r] = m[r][0] * x + m[r][1] * y + m[r][2] * z + m[r][3];
    if (!(img[2] > 0)) continue;
    // Range-checked in double before the cast: a far-off point must not overflow int64.
    const double uf = std::round(img[0] / img[2]) - offset, vf = std::round(img[1] / img[2]) - offset;
    if (!(uf >= 0 && vf >= 0 && uf < static_cast<double>(width) && vf < static_cast<double>(height))) continue;
    const auto u = static_cast<int64_t>(uf), v = static_cast<int64_t>(vf);
    const float value = static_cast<float>(options.depth_is_velo_x ? x : img[2]);
    float& cell = d[v][u];
    if (cell == 0.f || value < cell) cell = value;  // nearest point wins
  }
  return depth;
}

int64_t count_non_finite_points(const torch::Tensor& points) {
  check_shape(points, "velodyne points", {-1, 4});
  return (~torch::isfinite(points.slice(1, 0, 3))).any(1).sum().item<int64_t>();
}

}  // namespace geo
