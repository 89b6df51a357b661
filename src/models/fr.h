// Feature refinement (FR): CBAM-style channel attention then spatial attention (Woo et al. 2018),
// as placed by the paper after every encoder stage and decoder stage (paper Sec. 3).
#pragma once

#include <torch/torch.h>

#include "models/conv.h"
#include "models/sync_batch_norm.h"

#include <utility>

namespace geo {

struct FeatureRefinementOptions {
  explicit FeatureRefinementOptions(int64_t channels_) : channels(channels_) {}
  int64_t channels;
  int64_t ratio = 16;       // hidden width C / r of the shared MLP (paper, CBAM)
  int64_t min_hidden = 1;   // hidden width never below this (C / r < 1 for C < 16)
  int64_t kernel = 7;       // spatial attention conv (CBAM)
  bool spatial_bn = false;  // BatchNorm after the spatial conv (CBAM's code; off in the paper)
};

struct FeatureRefinementImpl : torch::nn::Module {
  explicit FeatureRefinementImpl(const FeatureRefinementOptions& options);

  // F2 = (F * a_c) * a_s, same shape as x [B,C,H,W].
  torch::Tensor forward(const torch::Tensor& x);

  // a_c = sigmoid(MLP(avgpool F) + MLP(maxpool F)) [B,C,1,1].
  torch::Tensor channel_gate(const torch::Tensor& x);
  // a_s = sigmoid(conv7x7([max_c F1, mean_c F1])) [B,1,H,W].
  torch::Tensor spatial_gate(const torch::Tensor& f1);
  // The gates from their pooled inputs (max and mean over space [B,C,1,1], over the channels
  // [B,1,H,W]): for a caller that pools itself (the int8 path pools 8-bit features).
  torch::Tensor channel_gate_of(const torch::Tensor& max, const torch::Tensor& mean);
  torch::Tensor spatial_gate_of(const torch::Tensor& max, const torch::Tensor& mean);
  // The spatial gate from its convolution's output [B,1,H,W] (BatchNorm if any, sigmoid): for a
  // caller that convolves itself.
  torch::Tensor spatial_gate_from(const torch::Tensor& conv_out);

  FeatureRefinementOptions options;
  Conv2d mlp_in{nullptr}, mlp_out{nullptr}, spatial{nullptr};
  SyncBatchNorm2d spatial_bn{nullptr};
};
TORCH_MODULE(FeatureRefinement);

// (max, mean) of x [B,C,H,W] over the channels -> [B,1,H,W] each, or over the image -> [B,C,1,1]
// each: FR's pooling. On CPU one fused pass (and one backward pass) instead of amax and mean;
// same values and gradients as x.amax(...) and x.mean(...), ties in the max sharing its gradient
// evenly (tests/models/fr_test.cpp).
std::pair<torch::Tensor, torch::Tensor> max_mean_over_channels(const torch::Tensor& x);
std::pair<torch::Tensor, torch::Tensor> max_mean_over_space(const torch::Tensor& x);

}  // namespace geo
