// Pinhole camera geometry: intrinsics per pyramid scale, back-projection, projection, rigid flow
// (GeoNet's utils.py: compute_rigid_flow, bilinear_sampler). Pixel coordinates are x = 0..W-1, y = 0..H-1 (pixel centres at integers).
// Device and dtype follow the inputs.
#pragma once

#include <torch/torch.h>

#include <vector>

namespace geo {

// Intrinsics at pyramid scale s: fx, fy, cx, cy divided by 2^s (GeoNet). K: [B,3,3].
torch::Tensor scale_intrinsics(const torch::Tensor& K, int scale);

// K [3,3] of frames `from_h` x `from_w` for the same camera at `to_h` x `to_w` (float64): fx, cx
// scale with the width, fy, cy with the height.
torch::Tensor resized_intrinsics(const torch::Tensor& K, int64_t from_h, int64_t from_w, int64_t to_h, int64_t to_w);

// A window of a frame: columns x0..x0+width-1, rows y0..y0+height-1.
struct CropWindow {
  int64_t x0 = 0, y0 = 0, width = 0, height = 0;
};
// The largest window of a width x height frame with the aspect ratio of to_w x to_h: centred in x,
// at `y_position` in y (0 top, 0.5 centre, 1 bottom); the whole frame when it already has it.
CropWindow crop_to_aspect(int64_t width, int64_t height, int64_t to_w, int64_t to_h, double y_position = 0.5);
// K [3,3] of a frame cropped to `window` then resized to to_h x to_w (float64): the principal point
// moves with the window's corner, then everything scales with the resize.
torch::Tensor cropped_resized_intrinsics(const torch::Tensor& K, const CropWindow& window, int64_t to_h, int64_t to_w);

// [K at scale 0, 1, ..., num_scales-1].
std::vector<torch::Tensor> intrinsics_pyramid(const torch::Tensor& K, int num_scales);

// Homogeneous pixel grid [1,3,H,W]: (x, y, 1) with x = column, y = row.
torch::Tensor pixel_grid(int64_t height, int64_t width, const torch::TensorOptions& options);

// cam_from_pix: points = depth * K^-1 [x, y, 1]^T. depth [B,1,H,W], K [B,3,3] -> [B,3,H,W].
torch::Tensor back_project(const torch::Tensor& depth, const torch::Tensor& K);

// The inverses of a batch of 3x3 matrices M [B,3,3] (cameras), in closed form (the adjugate over the
// determinant; differentiable): torch::inverse's LAPACK call took ~4.6 ms per [4,3,3] batch inside a
// training step here (its threads woken beside LibTorch's), 7% of the step.
torch::Tensor inverse_3x3(const torch::Tensor& M);

// pix_from_cam: [x, y] = (K X)[0:2] / (z + eps). points [B,3,H,W], K [B,3,3] -> [B,2,H,W].
torch::Tensor project(const torch::Tensor& points, const torch::Tensor& K, double eps = 1e-10);

// b_from_a applied to points: [B,4,4] x [B,3,H,W] -> [B,3,H,W].
torch::Tensor transform_points(const torch::Tensor& b_from_a, const torch::Tensor& points);

// Rigid flow from the target into the source (GeoNet's utils.py: compute_rigid_flow, bilinear_sampler):
//   p_s = K T_{s<-t} D_t(p_t) K^-1 p_t,  flow = p_s - p_t.
// depth_tgt [B,1,H,W], src_from_tgt [B,4,4], K [B,3,3] (at this scale) -> [B,2,H,W].
// The backward flow (source into target) is rigid_flow(depth_src, inverse_transform(T), K).
torch::Tensor rigid_flow(const torch::Tensor& depth_tgt, const torch::Tensor& src_from_tgt, const torch::Tensor& K);

}  // namespace geo
