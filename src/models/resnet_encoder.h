// ResNet encoder of the DepthNet and FlowNet (GeoNet's resnet50 encoder, with the paper's FR).
//
// conv1 7x7/2 (64) -> maxpool 3x3/2 -> four residual stages, each halving the resolution
// (GeoNet puts the stride in the last block of a stage). Depth 50: bottleneck blocks 3,4,6,3 with a
// 1x1 projection shortcut in every block (GeoNet/monodepth); depth 18/34: basic blocks 2,2,2,2 /
// 3,4,6,3. An FR follows each residual stage ("Refined1..4").
#pragma once

#include <torch/torch.h>

#include <vector>

#include "models/fr.h"
#include "models/conv_bn.h"

namespace geo {

struct ResNetEncoderOptions {
  int64_t in_channels = 3;   // 3 for DepthNet, 12 for FlowNet
  int depth = 50;            // ResNet-50 (paper)
  bool use_fr = true;        // FR after each residual stage (paper)
  int64_t fr_ratio = 16;     // paper
  bool fr_spatial_bn = false;
};

struct ResNetEncoderImpl : torch::nn::Module {
  explicit ResNetEncoderImpl(const ResNetEncoderOptions& options);

  // Six features: conv1 (1/2), pool1 (1/4), stage1..4 (1/8 .. 1/64); channels in channels().
  std::vector<torch::Tensor> forward(const torch::Tensor& x);

  // {64, 64, 256, 512, 1024, 2048} for depth 50 (paper); {64, 64, 64, 128, 256, 512} otherwise.
  const std::vector<int64_t>& channels() const { return channels_; }

  ResNetEncoderOptions options;
  ConvBn conv1{nullptr};
  std::vector<torch::nn::Sequential> stages;
  std::vector<FeatureRefinement> refine;  // empty when FR is off

 private:
  std::vector<int64_t> channels_;
};
TORCH_MODULE(ResNetEncoder);

}  // namespace geo
