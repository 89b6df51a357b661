// Pinhole camera geometry: intrinsics per pyramid scale, back-projection, projection, rigid flow
// (GeoNet's utils.py: compute_rigid_flow, bilinear_sampler). Pixel coordinates are x = 0..W-1, y = 0..H-1 (pixel centres at integers).
// Device and dtype follow the inputs.
#pragma once

#include <torch/torch.h>

#include <vector>

namespace geo {

// Intrinsics at pyramid scale s: fx, fy, cx, cy divided by 2^s (GeoNet). K: [B,3,3].
torch::Tensor scale_intrinsics(const torch::Tensor& K, int scale);

// [K at scale 0, 1, ..., num_scales-1].
std::vector<torch::Tensor> intrinsics_pyramid(const torch::Tensor& K, int num_scales);

// Homogeneous pixel grid [1,3,H,W]: (x, y, 1) with x = column, y = row.
torch::Tensor pixel_grid(int64_t height, int64_t width, const torch::TensorOptions& options);

// cam_from_pix: points = depth * K^-1 [x, y, 1]^T. depth [B,1,H,W], K [B,3,3] -> [B,3,H,W].
torch::Tensor back_project(const torch::Tensor& depth, const torch::Tensor& K);

// pix_from_cam: [x, y] = (K X)[0:2] / (z + eps). points [B,3,H,W], K [B,3,3] -> [B,2,H,W].
torch::Tensor project(const torch::Tensor& points, const torch::Tensor& K, double eps = 1e-10);

// b_from_a applied to points: [B,4,4] x [B,3,H,W] -> [B,3,H,W].
torch::Tensor transform_points(const torch::Tensor& b_from_a, const torch::Tensor& points);

// Rigid flow from the target into the source (GeoNet's utils.py: compute_rigid_flow, bilinear_sampler):
//   p_s = K T_{s<-t} D_t(p_t) K^-1 p_t,  flow = p_s - p_t.
// depth_tgt [B,1,H,W], src_from_tgt [B,4,4], K [B,3,3] (at this scale) -> [B,2,H,W].
// The backward flow (source into target) is rigid_flow(depth_src, inverse_transform(T), K).
torch::Tensor rigid_flow(const torch::Tensor& depth_tgt, const torch::Tensor& src_from_tgt,
                         const torch::Tensor& K);

}  // namespace geo
