// Bilinear warping of an image by a flow field (reference.md Sec. 2).
#pragma once

#include <torch/torch.h>

namespace geo {

struct Warped {
  torch::Tensor image;  // [B,C,H,W]: image sampled at p + flow(p), border-clamped (GeoNet)
  torch::Tensor valid;  // [B,1,H,W] in {0,1}: 1 where p + flow(p) lies inside [0,W-1]x[0,H-1]
};

// out(p) = image(p + flow(p)), bilinear. image [B,C,H,W], flow [B,2,H,W] in pixels (u = x, v = y).
// Uses grid_sample with align_corners = true, so pixel x maps to 2x/(W-1) - 1 exactly at the
// corner pixel centres; samples outside are clamped to the border and flagged in `valid`.
Warped warp(const torch::Tensor& image, const torch::Tensor& flow);

}  // namespace geo
