// Forward-backward flow reasoning: occlusion (paper eq. 13) and geometric consistency (eqs. 14-15).
#pragma once

#include <torch/torch.h>

#include "geometry/warp.h"

namespace geo {

// W_b(p + W_f(p)): the backward flow sampled where the forward flow points. [B,2,H,W] each.
// Out of view it is 0 (GeoNet's sampler, kZero) or the border value (kBorder).
torch::Tensor backward_at_forward(const torch::Tensor& flow_fw, const torch::Tensor& flow_bw, OutOfView out_of_view);

// Visibility (paper eq. 13): 1 where
//   |W_f + W_b(p+W_f)|^2 < alpha1 (|W_f|^2 + |W_b(p+W_f)|^2) + alpha2, else 0 (occluded).
// flow_fw, bw_at_fw [B,2,H,W] -> [B,1,H,W], no gradient.
torch::Tensor visibility_mask(const torch::Tensor& flow_fw, const torch::Tensor& bw_at_fw, double alpha1,
                              double alpha2);

struct Consistency {
  torch::Tensor loss;  // scalar: masked mean of |W_f + W_b(p+W_f)| over (u, v) and the mask
  torch::Tensor mask;  // [B,1,H,W]: pixels inside the bound (no gradient)
};

// Geometric consistency (paper eqs. 14-15, GeoNet): diff = |W_f + W_b(p+W_f)|, pixels with
//   ||diff|| * k < max(a, b * ||W_f|| * k), k = 2^scale if scale_factor (GeoNet) else 1,
// the bound without gradient; norms are GeoNet's ||(|x| + 1e-10)||_2.
Consistency geometric_consistency(const torch::Tensor& flow_fw, const torch::Tensor& bw_at_fw, double a, double b,
                                  int scale, bool scale_factor);

}  // namespace geo
