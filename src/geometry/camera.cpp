#include "geometry/camera.h"

#include "core/tensor_checks.h"

namespace geo {

torch::Tensor scale_intrinsics(const torch::Tensor& K, int scale) {
  check_shape(K, "K", {-1, 3, 3});
  TORCH_CHECK(scale >= 0, "scale must be >= 0, got ", scale);
  auto factor = torch::ones({1, 3, 1}, K.options());
  factor.narrow(1, 0, 2).fill_(1.0 / static_cast<double>(int64_t{1} << scale));
  return K * factor;  // rows 0 and 1 (fx, 0, cx / 0, fy, cy) scale; row 2 stays (0, 0, 1)
}

std::vector<torch::Tensor> intrinsics_pyramid(const torch::Tensor& K, int num_scales) {
  std::vector<torch::Tensor> out;
  for (int s = 0; s < num_scales; ++s) out.push_back(scale_intrinsics(K, s));
  return out;
}

torch::Tensor pixel_grid(int64_t height, int64_t width, const torch::TensorOptions& options) {
  const auto ys = torch::arange(height, options).view({height, 1}).expand({height, width});
  const auto xs = torch::arange(width, options).view({1, width}).expand({height, width});
  return torch::stack({xs, ys, torch::ones({height, width}, options)}, 0).unsqueeze(0);
}

torch::Tensor back_project(const torch::Tensor& depth, const torch::Tensor& K) {
  check_shape(depth, "depth", {-1, 1, -1, -1});
  check_shape(K, "K", {depth.size(0), 3, 3});
  const auto B = depth.size(0), H = depth.size(2), W = depth.size(3);
  const auto pix = pixel_grid(H, W, depth.options()).view({1, 3, H * W});
  const auto rays = K.inverse().matmul(pix);  // [B,3,HW]
  return (rays * depth.view({B, 1, H * W})).view({B, 3, H, W});
}

torch::Tensor project(const torch::Tensor& points, const torch::Tensor& K, double eps) {
  check_shape(points, "points", {-1, 3, -1, -1});
  check_shape(K, "K", {points.size(0), 3, 3});
  const auto B = points.size(0), H = points.size(2), W = points.size(3);
  const auto p = K.matmul(points.view({B, 3, H * W}));  // [B,3,HW]
  const auto xy = p.narrow(1, 0, 2) / (p.narrow(1, 2, 1) + eps);
  return xy.view({B, 2, H, W});
}

torch::Tensor transform_points(const torch::Tensor& b_from_a, const torch::Tensor& points) {
  check_shape(points, "points", {-1, 3, -1, -1});
  check_shape(b_from_a, "b_from_a", {points.size(0), 4, 4});
  const auto B = points.size(0), H = points.size(2), W = points.size(3);
  const auto R = b_from_a.narrow(1, 0, 3).narrow(2, 0, 3);
  const auto t = b_from_a.narrow(1, 0, 3).narrow(2, 3, 1);
  return (R.matmul(points.view({B, 3, H * W})) + t).view({B, 3, H, W});
}

torch::Tensor rigid_flow(const torch::Tensor& depth_tgt, const torch::Tensor& src_from_tgt,
                         const torch::Tensor& K) {
  check_shape(depth_tgt, "depth_tgt", {-1, 1, -1, -1});
  check_shape(src_from_tgt, "src_from_tgt", {depth_tgt.size(0), 4, 4});
  check_shape(K, "K", {depth_tgt.size(0), 3, 3});
  const auto H = depth_tgt.size(2), W = depth_tgt.size(3);
  const auto points_src = transform_points(src_from_tgt, back_project(depth_tgt, K));
  const auto grid = pixel_grid(H, W, depth_tgt.options()).narrow(1, 0, 2);
  return project(points_src, K) - grid;
}

}  // namespace geo
