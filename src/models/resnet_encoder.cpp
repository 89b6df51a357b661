#include "models/resnet_encoder.h"

#include "models/graph.h"

namespace geo {

BottleneckImpl::BottleneckImpl(int64_t in, int64_t n, int64_t stride) {
  c1 = register_module("conv1", ConvBn(in, n, 1));
  c2 = register_module("conv2", ConvBn(n, n, 3, stride));
  c3 = register_module("conv3", ConvBn(n, 4 * n, 1, 1, /*relu=*/false));
  proj = register_module("shortcut", ConvBn(in, 4 * n, 1, stride, false));
}

torch::Tensor BottleneckImpl::forward(const torch::Tensor& x) {
  FloatOps ops;
  return bottleneck_graph(*this, ops, x);
}

BasicBlockImpl::BasicBlockImpl(int64_t in, int64_t n, int64_t stride) {
  c1 = register_module("conv1", ConvBn(in, n, 3, stride));
  c2 = register_module("conv2", ConvBn(n, n, 3, 1, /*relu=*/false));
  if (in != n || stride != 1) proj = register_module("shortcut", ConvBn(in, n, 1, stride, false));
}

torch::Tensor BasicBlockImpl::forward(const torch::Tensor& x) {
  FloatOps ops;
  return basic_block_graph(*this, ops, x);
}

ResNetEncoderImpl::ResNetEncoderImpl(const ResNetEncoderOptions& o) : options(o) {
  std::vector<int> blocks;
  const bool bottleneck = o.depth == 50;
  if (o.depth == 18) blocks = {2, 2, 2, 2};
  else if (o.depth == 34 || o.depth == 50) blocks = {3, 4, 6, 3};
  else TORCH_CHECK(false, "encoder depth must be 18, 34 or 50, got ", o.depth);
  TORCH_CHECK(o.in_channels >= 1, "in_channels must be >= 1, got ", o.in_channels);

  conv1 = register_module("conv1", ConvBn(o.in_channels, 64, 7, 2));
  channels_ = {64, 64};
  int64_t in = 64;
  const int64_t widths[4] = {64, 128, 256, 512};
  for (int s = 0; s < 4; ++s) {
    torch::nn::Sequential stage;
    for (int b = 0; b < blocks[s]; ++b) {
      const int64_t stride = b == blocks[s] - 1 ? 2 : 1;  // GeoNet: stride in the last block
      if (bottleneck) {
        stage->push_back(Bottleneck(in, widths[s], stride));
        in = 4 * widths[s];
      } else {
        stage->push_back(BasicBlock(in, widths[s], stride));
        in = widths[s];
      }
    }
    stages.push_back(register_module("stage" + std::to_string(s + 1), stage));
    channels_.push_back(in);
    if (o.use_fr) {
      FeatureRefinementOptions fo(in);
      fo.ratio = o.fr_ratio;
      fo.spatial_bn = o.fr_spatial_bn;
      refine.push_back(register_module("refined" + std::to_string(s + 1), FeatureRefinement(fo)));
    }
  }
}

std::vector<torch::Tensor> ResNetEncoderImpl::forward(const torch::Tensor& x) {
  FloatOps ops;
  return encoder_graph(*this, ops, x);
}

}  // namespace geo
