#include "geometry/pose.h"

#include "core/tensor_checks.h"

#include <cmath>

namespace geo {

torch::Tensor euler_to_rotation(const torch::Tensor& angles) {
  check_shape(angles, "angles", {-1, 3});
  const auto rx = angles.select(1, 0), ry = angles.select(1, 1), rz = angles.select(1, 2);
  const auto zero = torch::zeros_like(rx), one = torch::ones_like(rx);
  auto mat = [](std::initializer_list<torch::Tensor> e) {
    return torch::stack(std::vector<torch::Tensor>(e), 1).view({-1, 3, 3});
  };
  const auto cx = rx.cos(), sx = rx.sin(), cy = ry.cos(), sy = ry.sin(), cz = rz.cos(), sz = rz.sin();
  const auto Rx = mat({one, zero, zero, zero, cx, -sx, zero, sx, cx});
  const auto Ry = mat({cy, zero, sy, zero, one, zero, -sy, zero, cy});
  const auto Rz = mat({cz, -sz, zero, sz, cz, zero, zero, zero, one});
  return Rx.matmul(Ry).matmul(Rz);
}

namespace {
torch::Tensor assemble(const torch::Tensor& R, const torch::Tensor& t) {
  const auto B = R.size(0);
  auto bottom = torch::zeros({B, 1, 4}, R.options());
  bottom.select(2, 3).fill_(1);
  return torch::cat({torch::cat({R, t.unsqueeze(2)}, 2), bottom}, 1);
}
}  // namespace

torch::Tensor pose_vec_to_matrix(const torch::Tensor& pose_vec) {
  check_shape(pose_vec, "pose_vec", {-1, 6});
  // GeoNet's euler2mat clips each angle to [-pi, pi] (tf.clip_by_value: no gradient outside).
  const auto angles = pose_vec.narrow(1, 3, 3).clamp(-M_PI, M_PI);
  return assemble(euler_to_rotation(angles), pose_vec.narrow(1, 0, 3));
}

torch::Tensor matrix_to_pose_vec(const torch::Tensor& T) {
  check_shape(T, "transform", {-1, 4, 4});
  // R = Rx Ry Rz has R02 = sin(ry), R12 = -sin(rx) cos(ry), R22 = cos(rx) cos(ry),
  // R01 = -cos(ry) sin(rz), R00 = cos(ry) cos(rz).
  auto r = [&](int i, int j) { return T.select(1, i).select(1, j); };
  const auto cy = torch::sqrt(r(0, 0) * r(0, 0) + r(0, 1) * r(0, 1));
  const auto ry = torch::atan2(r(0, 2), cy);
  const auto rx = torch::atan2(-r(1, 2), r(2, 2));
  const auto rz = torch::atan2(-r(0, 1), r(0, 0));
  const auto t = T.narrow(1, 0, 3).select(2, 3);
  return torch::cat({t, torch::stack({rx, ry, rz}, 1)}, 1);
}

torch::Tensor axisangle_to_matrix(const torch::Tensor& axisangle, const torch::Tensor& translation) {
  check_shape(axisangle, "axisangle", {-1, 3});
  check_shape(translation, "translation", {axisangle.size(0), 3});
  const auto angle = axisangle.norm(2, 1, /*keepdim=*/true);  // [B,1]
  const auto axis = axisangle / angle.clamp_min(1e-12);       // [B,3]
  const auto x = axis.select(1, 0), y = axis.select(1, 1), z = axis.select(1, 2);
  const auto c = angle.squeeze(1).cos(), s = angle.squeeze(1).sin(), C = 1 - c;
  const auto R = torch::stack({c + x * x * C, x * y * C - z * s, x * z * C + y * s, y * x * C + z * s, c + y * y * C,
                               y * z * C - x * s, z * x * C - y * s, z * y * C + x * s, c + z * z * C},
                              1)
                     .view({-1, 3, 3});
  return assemble(R, translation);
}

torch::Tensor inverse_transform(const torch::Tensor& T) {
  check_shape(T, "transform", {-1, 4, 4});
  const auto R = T.narrow(1, 0, 3).narrow(2, 0, 3);
  const auto t = T.narrow(1, 0, 3).narrow(2, 3, 1);
  const auto Rt = R.transpose(1, 2);
  return assemble(Rt, (-Rt.matmul(t)).squeeze(2));
}

torch::Tensor compose(const torch::Tensor& c_from_b, const torch::Tensor& b_from_a) {
  check_shape(c_from_b, "c_from_b", {-1, 4, 4});
  check_shape(b_from_a, "b_from_a", {c_from_b.size(0), 4, 4});
  return c_from_b.matmul(b_from_a);
}

}  // namespace geo
