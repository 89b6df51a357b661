// DepthNet: ResNet-50 encoder-decoder with FR predicting disparity at 4 scales (paper Sec. 3).
#pragma once

#include <torch/torch.h>

#include <vector>

#include "models/decoder.h"

namespace geo {

struct DepthNetOptions {
  int encoder_depth = 50;                          // ResNet-50 (paper)
  bool use_fr = true;                              // FR on (paper); false = Table 4 "w/o FR"
  bool fr_encoder = true;                          // Refined1..4 (paper)
  bool fr_decoder = true;                          // Refined5..10 (paper)
  int64_t fr_ratio = 16;                           // paper
  bool fr_spatial_bn = false;                      // CBAM's code option
  UpsampleMode upsample = UpsampleMode::kNearest;  // GeoNet
  double disp_scale = 5.0;                         // disp = 5 sigmoid(x) + 0.01 (GeoNet ResNet-50 scaling)
  double min_disp = 0.01;                          // GeoNet
};

// The encoder-decoder options of these settings for `in` input and `out` output channels
// (shared with the FlowNet, which has the same design).
EncoderDecoderOptions encoder_decoder_options(const DepthNetOptions& o, int64_t in, int64_t out);

struct DepthOutput {
  std::vector<torch::Tensor> disp;  // disp[s]: [B,1,~H/2^s,~W/2^s], in (0.01, 5.01); depth = 1/disp
};

struct DepthNetImpl : torch::nn::Module {
  explicit DepthNetImpl(const DepthNetOptions& options = {});
  // image: [B,3,H,W] RGB in [0,1], any size >= 1 (multiples of 8 give exact 2^s scales).
  DepthOutput forward(const torch::Tensor& image);

  DepthNetOptions options;
  // The type of the weights and the arithmetic: float32, or bfloat16 for inference
  // (Networks::prepare_inference); inputs are cast to it and the outputs are float32.
  torch::Dtype compute_dtype = torch::kFloat32;
  EncoderDecoder net{nullptr};
};
TORCH_MODULE(DepthNet);

}  // namespace geo
