// PoseNet (paper Sec. 3, GeoNet's pose_net): eight convolutions over the stacked snippet.
#pragma once

#include <torch/torch.h>

#include <vector>

#include "models/layers.h"

namespace geo {

struct PoseNetOptions {
  int seq_length = 3;          // target + 2 sources (depth training); 5 for odometry
  double output_scale = 0.01;  // pose = 0.01 * mean over pixels (GeoNet)
};

struct PoseNetImpl : torch::nn::Module {
  explicit PoseNetImpl(const PoseNetOptions& options = {});

  // tgt [B,3,H,W] and seq_length-1 sources, RGB in [0,1] -> [B, num_sources, 6] pose vectors
  // [tx,ty,tz,rx,ry,rz], src_from_tgt (geometry/pose.h).
  torch::Tensor forward(const torch::Tensor& tgt, const std::vector<torch::Tensor>& srcs);

  int num_sources() const { return options.seq_length - 1; }

  PoseNetOptions options;
  torch::Dtype compute_dtype = torch::kFloat32;  // as DepthNetImpl::compute_dtype
  std::vector<ConvBn> convs;     // conv1..conv7: 16 (7x7), 32 (5x5), 64, 128, 256, 256, 256 (3x3), /2
  torch::nn::Conv2d pred{nullptr};  // 1x1 to 6 * num_sources, no BN / activation
};
TORCH_MODULE(PoseNet);

}  // namespace geo
