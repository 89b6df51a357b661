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

// GeoNet's resconv: 1x1 (n) -> 3x3/stride (n) -> 1x1 (4n, no ReLU) + shortcut, then ReLU.
// The shortcut is always a projection (1x1/stride + BN): GeoNet (after monodepth) tests
// `tf.shape(x)[3] != num_layers`, which is always true in TF1, and keeps it "for consistency".
// This is what makes GeoNet's ResNet-50 DepthNet 58.5 M parameters rather than 49.5 M.
struct BottleneckImpl : torch::nn::Module {
  BottleneckImpl(int64_t in, int64_t n, int64_t stride);
  torch::Tensor forward(const torch::Tensor& x);
  ConvBn c1{nullptr}, c2{nullptr}, c3{nullptr}, proj{nullptr};
};
TORCH_MODULE(Bottleneck);

// Basic block (ResNet-18/34): 3x3/stride -> 3x3 (no ReLU) + shortcut (a projection where the
// shape changes, else the input), then ReLU.
struct BasicBlockImpl : torch::nn::Module {
  BasicBlockImpl(int64_t in, int64_t n, int64_t stride);
  torch::Tensor forward(const torch::Tensor& x);
  ConvBn c1{nullptr}, c2{nullptr}, proj{nullptr};
};
TORCH_MODULE(BasicBlock);

struct ResNetEncoderOptions {
  int64_t in_channels = 3;  // 3 for DepthNet, 12 for FlowNet
  int depth = 50;           // ResNet-50 (paper)
  bool use_fr = true;       // FR after each residual stage (paper)
  int64_t fr_ratio = 16;    // paper
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
