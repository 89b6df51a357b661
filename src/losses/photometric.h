// Photometric reconstruction error (paper Sec. 3.3-3.6; GeoNet's image_similarity).
#pragma once

#include <torch/torch.h>

#include <vector>

namespace geo {

// SSIM map of x and y [B,C,H,W] -> [B,C,H,W]: 3x3 mean windows, C1 = 0.01^2, C2 = 0.03^2.
// Windows at the border average only the pixels inside the image (TensorFlow's 'SAME' average
// pooling, as in GeoNet), so the map keeps the input size and per-pixel masks apply.
torch::Tensor ssim(const torch::Tensor& x, const torch::Tensor& y);

// Per-pixel, per-channel photometric error [B,C,H,W]:
//   alpha * clip((1 - SSIM) / 2, 0, 1) + (1 - alpha) * |x - y|   (GeoNet's image_similarity).
// On CPU (float32/float64) one fused pass per image plane with a hand-written backward; elsewhere
// photometric_error_channels_reference. Both agree to rounding (tests/losses).
torch::Tensor photometric_error_channels(const torch::Tensor& x, const torch::Tensor& y, double alpha);
// The same composed of tensor operations (ssim() above, clamp, abs), gradients by autograd.
torch::Tensor photometric_error_channels_reference(const torch::Tensor& x, const torch::Tensor& y, double alpha);

// Per-pixel photometric error, mean over channels -> [B,1,H,W]:
//   alpha * clip((1 - SSIM) / 2, 0, 1) + (1 - alpha) * |x - y|   (alpha = 0.85 in the paper).
torch::Tensor photometric_error(const torch::Tensor& x, const torch::Tensor& y, double alpha);

// L2 norm over the channels [B,C,H,W] -> [B,1,H,W] (the FlowNet's input "L2 norm of the rigid
// error"; a plain sum of squares: at::norm over 3 channels is slow). Differentiable where grad mode
// is on, with a zero gradient (not NaN) where the norm is 0.
torch::Tensor channel_l2_norm(const torch::Tensor& x);

// [image, image/2, ...]: each level the 2x2 mean of the previous (area resize, GeoNet).
// Sides must be divisible by 2^(num_scales-1).
std::vector<torch::Tensor> image_pyramid(const torch::Tensor& image, int num_scales);

// sum(value * mask) / max(sum(mask) * C_value / C_mask, eps): the mean over masked elements.
// value [B,C,H,W], mask [B,1,H,W] (broadcast over C). An all-zero mask gives 0.
torch::Tensor masked_mean(const torch::Tensor& value, const torch::Tensor& mask);

}  // namespace geo
