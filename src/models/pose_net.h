// PoseNet (paper Sec. 3, GeoNet's pose_net): eight convolutions over the stacked snippet.
#pragma once

#include <torch/torch.h>

#include <memory>
#include <vector>

#include "models/conv_bn.h"
#include "models/int8.h"

namespace geo {

struct PoseNetOptions {
  int seq_length = 3;          // target + 2 sources (depth training); 5 for odometry
  double output_scale = 0.01;  // pose = 0.01 * mean over pixels (GeoNet)
  // The learned camera's head output is scaled likewise: unscaled, Adam moves its 256 weights per
  // output together by about 256 x lr a step and the focal length collapses within 50 steps while
  // the poses are still noise (fx 144 -> 33 on the synthetic world); 0.01 barely moves it in 300
  // steps (144 -> 137, truth 121); 0.05 reaches the truth's 10% by step 100 (docs/video.md).
  double intrinsics_output_scale = 0.05;
  // The camera from the images (Gordon et al., ICCV 2019: a 1x1 convolution on the motion network's
  // spatially averaged bottleneck): fx = softplus(a) W, fy = softplus(b) W (square pixels start
  // equal), cx = (c + 0.5) W, cy = (d + 0.5) H. Zero-initialised: fx = fy = ln 2 W = 0.69 W (KITTI:
  // 0.58 W) and the principal point at the centre.
  bool learn_intrinsics = false;
};

struct PoseOutput {
  torch::Tensor poses;  // [B, num_sources, 6] as forward()
  torch::Tensor K;      // [B,3,3] float32 at the input's size when learn_intrinsics, else undefined
};

struct PoseNetImpl : torch::nn::Module {
  explicit PoseNetImpl(const PoseNetOptions& options = {});

  // tgt [B,3,H,W] and seq_length-1 sources, RGB in [0,1] -> [B, num_sources, 6] pose vectors
  // [tx,ty,tz,rx,ry,rz], src_from_tgt (geometry/pose.h).
  torch::Tensor forward(const torch::Tensor& tgt, const std::vector<torch::Tensor>& srcs);
  // The poses and, with learn_intrinsics, the camera of the snippet.
  PoseOutput predict(const torch::Tensor& tgt, const std::vector<torch::Tensor>& srcs);

  int num_sources() const { return options.seq_length - 1; }

  PoseNetOptions options;
  torch::Dtype compute_dtype = torch::kFloat32;  // as DepthNetImpl::compute_dtype
  std::vector<ConvBn> convs;                     // conv1..conv7: 16 (7x7), 32 (5x5), 64, 128, 256, 256, 256 (3x3), /2
  Conv2d pred{nullptr};                          // 1x1 to 6 * num_sources, no BN / activation
  Conv2d intrinsics{nullptr};                    // learn_intrinsics: 1x1, 256 -> 4 on the averaged conv7 output
  // Set by observe_int8 (models/int8.h): conv1..conv7 calibrate, then (quantize_int8) run in int8.
  std::shared_ptr<Int8PoseNet> int8;
};
TORCH_MODULE(PoseNet);

}  // namespace geo
