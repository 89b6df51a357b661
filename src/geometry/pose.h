// Camera motion: 6-DoF pose vectors <-> 4x4 rigid transforms.
//
// Pose vector (PoseNet output, GeoNet convention): [tx, ty, tz, rx, ry, rz], the transform
// src_from_tgt (target camera -> source camera), rotation R = Rx(rx) * Ry(ry) * Rz(rz) from Euler
// angles in radians, X' = R X + t.
//
// monodepth2 convention (optional): axis-angle a (|a| = angle, a/|a| = axis, Rodrigues) plus the
// translation, also X' = R X + t. Both forms describe the same [R|t]; only the rotation
// parameterisation differs, so converting is matrix_to_pose_vec(axisangle_to_matrix(a, t)).
#pragma once

#include <torch/torch.h>

namespace geo {

// [B,6] -> [B,4,4]; each angle clipped to [-pi, pi] first (GeoNet's euler2mat).
torch::Tensor pose_vec_to_matrix(const torch::Tensor& pose_vec);

// [B,4,4] -> [B,6] with ry in [-pi/2, pi/2] and rx, rz in (-pi, pi]. Inverse of
// pose_vec_to_matrix for vectors in that range (away from the gimbal lock |ry| = pi/2).
torch::Tensor matrix_to_pose_vec(const torch::Tensor& transform);

// Rotation matrix R = Rx * Ry * Rz from [B,3] Euler angles (rx, ry, rz) -> [B,3,3].
torch::Tensor euler_to_rotation(const torch::Tensor& angles);

// Rodrigues: axis-angle [B,3] and translation [B,3] -> [B,4,4] (monodepth2's parameterisation).
torch::Tensor axisangle_to_matrix(const torch::Tensor& axisangle, const torch::Tensor& translation);

// Inverse of a rigid transform [B,4,4]: [R^T | -R^T t].
torch::Tensor inverse_transform(const torch::Tensor& transform);

// c_from_a = c_from_b * b_from_a, all [B,4,4].
torch::Tensor compose(const torch::Tensor& c_from_b, const torch::Tensor& b_from_a);

}  // namespace geo
