// The int8 networks' hand-written byte kernels (models/int8.cpp's graphs call them): quantizing a
// float feature into NHWC bytes, concatenating 8-bit features, and FR applied to an 8-bit feature.
// Each loop is compiled for AVX-512 and AVX2 besides the baseline (GCC's function multi-versioning).
#pragma once

#include <torch/torch.h>

#include <cstdint>
#include <vector>

namespace geo {

struct FeatureRefinementImpl;

// x float [B,C,H,W] -> quint8 [B,C,H,W] channels-last (NHWC bytes) with (scale, zero_point): what
// at::quantize_per_tensor computes (ties rounded up rather than to even), vectorised.
torch::Tensor quantize_to_nhwc(const torch::Tensor& x, double scale, int64_t zero_point);

// A convolution's kernel w [Co,...] float -> qint8 per output channel, symmetric (scale
// max|w_c| / 127, zero point 0): what at::quantize_per_channel computes with those scales, exactly,
// in one vectorised pass for the scales and one for the bytes (ATen's took a quarter of opening an
// int8 model). channel_factor [Co] (float32), when given: the kernel w x channel_factor per output
// channel is quantized (BatchNorm's folding: the same bytes as quantizing the product made in
// float32), without making that product.
torch::Tensor quantize_weight_per_channel(const torch::Tensor& weight, const torch::Tensor& channel_factor = {});

// quint8 [B,Ci,H,W] tensors concatenated along the channels into quint8 channels-last with (scale,
// zero_point), each requantized on the way (quantized::cat's result in one vectorised pass: it took
// ~2 ms of each int8 encoder-decoder here).
torch::Tensor cat_int8(const std::vector<torch::Tensor>& parts, double scale, int64_t zero_point);

// FR on an 8-bit NHWC feature q (quint8): the channel gate from q's max and mean over space, the
// spatial gate from the max and mean over the channels of q * a_c (both pooled from the 8-bit
// values), then q * a_c * a_s requantized to (scale, zero_point) in one pass; the gates themselves
// (MLP, 7x7 convolution, sigmoids) in float, as in the float network.
torch::Tensor int8_feature_refinement(FeatureRefinementImpl& fr, const torch::Tensor& q, double scale,
                                      int64_t zero_point);

// The four 2x2 phases of an upsampling convolution [B,4*Co,h+1,w+1] quint8 NHWC (phase (a, b) of
// output pixel (2i+a, 2j+b) in channels (2a+b)*Co.. of pixel (i+a, j+b)) -> its output [B,Co,2h,2w]
// quint8 NHWC, with the same scale and zero point.
torch::Tensor interleave_phases_int8(const torch::Tensor& phases, int64_t Co);

}  // namespace geo
