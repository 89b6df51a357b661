// A 3x3 convolution of a nearest-neighbour x2 upsampled image, computed at the image's resolution.
#pragma once

#include <torch/torch.h>

namespace geo {

// conv2d(nearest ×2 upsampling of x, 3x3 weight, zero padding 1) without building the upsampled
// image. Output pixel (2i+a, 2j+b) only sees input rows {i-1, i} (a = 0) or {i, i+1} (a = 1), and
// likewise for columns, so each of the four phases (a, b) is a 2x2 convolution of x with summed
// taps (rows: a = 0 -> (w0, w1+w2), a = 1 -> (w0+w1, w2)). One conv of x with the four phase
// kernels stacked, then the phases interleaved. x [B,Ci,h,w], weight [Co,Ci,3,3], bias [Co] or
// undefined -> [B,Co,2h,2w]. Differentiable in x, weight and bias.
torch::Tensor conv3x3_of_upsampled(const torch::Tensor& x, const torch::Tensor& weight, const torch::Tensor& bias);

// Its parts, for modules that prepack the kernels (ConvBn): the [4*Co, Ci, 2, 2] phase kernels of a
// [Co, Ci, 3, 3] kernel, and y [B,2,2,Co,h+1,w+1] (the four phases' outputs) interleaved into
// [B,Co,2h,2w].
torch::Tensor phase_kernels(const torch::Tensor& weight);
torch::Tensor interleave_phases(const torch::Tensor& phases);
// The same for inference (no autograd), into a channels-last [B,Co,2h,2w], ReLU applied on the way
// where `relu`: what the next (prepacked, channels-last) convolution reads as it lies.
torch::Tensor interleave_phases_channels_last(const torch::Tensor& phases, bool relu);

}  // namespace geo
