#include "geometry/camera.h"

#include <algorithm>
#include <cmath>

#include "core/tensor_checks.h"

namespace geo {

torch::Tensor scale_intrinsics(const torch::Tensor& K, int scale) {
  check_shape(K, "K", {-1, 3, 3});
  TORCH_CHECK(scale >= 0, "scale must be >= 0, got ", scale);
  auto factor = torch::ones({1, 3, 1}, K.options());
  factor.narrow(1, 0, 2).fill_(1.0 / static_cast<double>(int64_t{1} << scale));
  return K * factor;  // rows 0 and 1 (fx, 0, cx / 0, fy, cy) scale; row 2 stays (0, 0, 1)
}

torch::Tensor resized_intrinsics(const torch::Tensor& K, int64_t from_h, int64_t from_w, int64_t to_h, int64_t to_w) {
  TORCH_CHECK(K.dim() == 2 && K.size(0) == 3 && K.size(1) == 3, "K must be [3,3], got ", K.sizes());
  TORCH_CHECK(from_h > 0 && from_w > 0 && to_h > 0 && to_w > 0, "sizes must be positive, got ", from_w, "x", from_h,
              " -> ", to_w, "x", to_h);
  auto out = K.to(torch::kFloat64).clone();
  out[0] *= static_cast<double>(to_w) / static_cast<double>(from_w);
  out[1] *= static_cast<double>(to_h) / static_cast<double>(from_h);
  return out;
}

CropWindow crop_to_aspect(int64_t width, int64_t height, int64_t to_w, int64_t to_h, double y_position) {
  TORCH_CHECK(width > 0 && height > 0 && to_w > 0 && to_h > 0, "sizes must be positive, got ", width, "x", height,
              " -> ", to_w, "x", to_h);
  CropWindow w{0, 0, width, height};
  // Compare width/height with to_w/to_h in integers: width * to_h vs height * to_w.
  if (width * to_h > height * to_w) {  // wider than the target: keep every row, centre the columns
    w.width = std::max<int64_t>(1, (height * to_w + to_h / 2) / to_h);
    w.x0 = (width - w.width) / 2;
  } else if (width * to_h < height * to_w) {  // taller: keep every column, rows at y_position
    w.height = std::max<int64_t>(1, (width * to_h + to_w / 2) / to_w);
    w.y0 = static_cast<int64_t>(std::lround(static_cast<double>(height - w.height) * std::clamp(y_position, 0.0, 1.0)));
  }
  return w;
}

torch::Tensor cropped_resized_intrinsics(const torch::Tensor& K, const CropWindow& window, int64_t to_h, int64_t to_w) {
  TORCH_CHECK(K.dim() == 2 && K.size(0) == 3 && K.size(1) == 3, "K must be [3,3], got ", K.sizes());
  auto shifted = K.to(torch::kFloat64).clone();
  shifted[0][2] -= static_cast<double>(window.x0);
  shifted[1][2] -= static_cast<double>(window.y0);
  return resized_intrinsics(shifted, window.height, window.width, to_h, to_w);
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

torch::Tensor inverse_3x3(const torch::Tensor& M) {
  check_shape(M, "M", {-1, 3, 3});
  const auto r0 = M.select(1, 0), r1 = M.select(1, 1), r2 = M.select(1, 2);
  // The inverse's columns: the cross products of the rows, over the determinant.
  const auto c0 = at::linalg_cross(r1, r2, -1), c1 = at::linalg_cross(r2, r0, -1), c2 = at::linalg_cross(r0, r1, -1);
  const auto det = (r0 * c0).sum(-1).view({-1, 1, 1});
  return torch::stack({c0, c1, c2}, -1) / det;
}

torch::Tensor back_project(const torch::Tensor& depth, const torch::Tensor& K) {
  check_shape(depth, "depth", {-1, 1, -1, -1});
  check_shape(K, "K", {depth.size(0), 3, 3});
  const auto B = depth.size(0), H = depth.size(2), W = depth.size(3);
  const auto pix = pixel_grid(H, W, depth.options()).view({1, 3, H * W});
  const auto rays = inverse_3x3(K).matmul(pix);  // [B,3,HW]
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

torch::Tensor rigid_flow(const torch::Tensor& depth_tgt, const torch::Tensor& src_from_tgt, const torch::Tensor& K) {
  check_shape(depth_tgt, "depth_tgt", {-1, 1, -1, -1});
  check_shape(src_from_tgt, "src_from_tgt", {depth_tgt.size(0), 4, 4});
  check_shape(K, "K", {depth_tgt.size(0), 3, 3});
  const auto H = depth_tgt.size(2), W = depth_tgt.size(3);
  const auto points_src = transform_points(src_from_tgt, back_project(depth_tgt, K));
  const auto grid = pixel_grid(H, W, depth_tgt.options()).narrow(1, 0, 2);
  return project(points_src, K) - grid;
}

}  // namespace geo
