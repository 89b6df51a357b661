// Residual FlowNet (paper Sec. 3, GeoNet's ResFlowNet with the paper's FR): the DepthNet
// design over a 12-channel input, predicting the non-rigid residual flow at 4 scales.
#pragma once

#include <torch/torch.h>

#include <vector>

#include "models/depth_net.h"

namespace geo {

struct FlowNetOptions {
  DepthNetOptions backbone;  // same encoder-decoder settings as the DepthNet (paper)
  double flow_scale = 0.1;   // residual = 0.1 * conv, in units of the image size (GeoNet)
  // The prediction convs start at zero (model.flow_zero_init), so the residual is 0 and the full
  // flow the rigid flow when the FlowNet starts training; GeoNet: Xavier like every other layer.
  bool zero_init_residual = false;
};

struct FlowOutput {
  std::vector<torch::Tensor> flow;  // flow[s]: [B,2,h_s,w_s] residual flow in pixels of scale s
};

// The 12 input channels of one direction: target and source (normalised to [-1,1]), the source
// warped by the rigid flow (normalised), the rigid flow (2, pixels) and the per-pixel L2 norm over
// colour channels of the rigid photometric error (1). All [B,*,H,W] at full resolution.
torch::Tensor flow_net_input(const torch::Tensor& tgt, const torch::Tensor& src, const torch::Tensor& rigid_warp,
                             const torch::Tensor& rigid_flow, const torch::Tensor& rigid_error_norm);

struct FlowNetImpl : torch::nn::Module {
  explicit FlowNetImpl(const FlowNetOptions& options = {});
  // input [B,12,H,W] from flow_net_input(). Full flow = residual + rigid flow (at each scale).
  FlowOutput forward(const torch::Tensor& input);

  FlowNetOptions options;
  torch::Dtype compute_dtype = torch::kFloat32;  // as DepthNetImpl::compute_dtype
  EncoderDecoder net{nullptr};
};
TORCH_MODULE(FlowNet);

}  // namespace geo
