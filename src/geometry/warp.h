// Bilinear warping of an image by a flow field (GeoNet's utils.py: compute_rigid_flow, bilinear_sampler).
#pragma once

#include <torch/torch.h>

namespace geo {

// What a sample that leaves the image returns.
enum class OutOfView {
  kZero,    // GeoNet's bilinear_sampler (utils.py): 0, with zero gradient, outside [0,W-1)x[0,H-1)
            // (its weights x1_safe - x and x - x0_safe cancel there, also exactly on x = W-1)
  kBorder,  // clamped to the border pixels (grid_sample's border padding)
};

struct Warped {
  torch::Tensor image;  // [B,C,H,W]: image sampled at p + flow(p), out-of-view per OutOfView
  torch::Tensor valid;  // [B,1,H,W] in {0,1}: 1 where p + flow(p) lies in the sampler's image
                        // ([0,W-1)x[0,H-1) for kZero, [0,W-1]x[0,H-1] for kBorder); no gradient
};

// out(p) = image(p + flow(p)), bilinear. image [B,C,H,W], flow [B,2,H,W] in pixels (u = x, v = y).
// Uses grid_sample with align_corners = true, so pixel x maps to 2x/(W-1) - 1 exactly at the
// corner pixel centres. kZero multiplies the in-view samples by `valid` (inside [0,W-1) both
// samplers interpolate the same four pixels, so this is GeoNet's sampler exactly).
Warped warp(const torch::Tensor& image, const torch::Tensor& flow, OutOfView out_of_view);

}  // namespace geo
