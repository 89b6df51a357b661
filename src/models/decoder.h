// The encoder-decoder shared by DepthNet and FlowNet (GeoNet's disp_net_res50 / resflow_net with
// the paper's FR after every decoder stage, "Refined5..10").
//
// Six stages (512, 256, 128, 64, 32, 16 channels): x2 upsample + 3x3 conv, resize to the skip
// (GeoNet's resize_like, so any input size works), concatenate the encoder skip of that scale and,
// from 1/4 down to full size, the upsampled coarser prediction; 3x3 conv; FR. Predictions (3x3 conv,
// no BN) at 1/8, 1/4, 1/2 and full resolution, through the head activation.
#pragma once

#include <torch/torch.h>

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "models/fr.h"
#include "models/conv_bn.h"
#include "models/int8.h"
#include "models/layers.h"
#include "models/resnet_encoder.h"

namespace geo {

struct EncoderDecoderOptions {
  ResNetEncoderOptions encoder;
  int64_t out_channels = 1;                        // 1 (disparity) or 2 (flow)
  bool fr_decoder = true;                          // FR after each decoder stage (paper)
  UpsampleMode upsample = UpsampleMode::kNearest;  // GeoNet
};

struct EncoderDecoderImpl : torch::nn::Module {
  using Head = std::function<torch::Tensor(const torch::Tensor&)>;
  EncoderDecoderImpl(const EncoderDecoderOptions& options, Head head);

  // 4 predictions, finest first: [0] full size (input's), [1] 1/2, [2] 1/4, [3] 1/8.
  std::vector<torch::Tensor> forward(const torch::Tensor& x);

  EncoderDecoderOptions options;
  Head head;
  ResNetEncoder encoder{nullptr};
  std::vector<ConvBn> upconv, iconv;      // index 0 = stage 6 (coarsest) ... 5 = stage 1
  std::vector<FeatureRefinement> refine;  // empty when decoder FR is off
  std::vector<Conv2d> pred;               // index 0 = 1/8 ... 3 = full
  // Set by observe_int8 (models/int8.h): forward calibrates, then (quantize_int8) runs in int8.
  std::shared_ptr<Int8EncoderDecoder> int8;
};
TORCH_MODULE(EncoderDecoder);

}  // namespace geo
