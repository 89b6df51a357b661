// One training forward pass over a batch (paper Sec. 3): DepthNet on every frame, PoseNet on the
// snippet, the rigid losses, then (when the stage trains flow) the residual FlowNet in both
// directions for every source and the flow losses. LibTorch only.
#pragma once

#include "core/config.h"
#include "losses/total_loss.h"
#include "pipeline/networks.h"

#include <optional>
#include <vector>

namespace geo {

struct StepOutput {
  LossTerms losses;
  std::vector<torch::Tensor> tgt_disp;  // target disparity per scale
  RigidTerms rigid;
  std::optional<FlowTerms> flow;
  PerSourceScale<torch::Tensor> fwd_full;  // full flows (residual + rigid), when flow ran
  torch::Tensor K;                         // [B,3,3] the learned camera (model.learn_intrinsics), else undefined
};

// tgt [B,3,H,W], srcs [B,N,3,H,W], K [B,3,3] on the networks' device. FlowNet inputs are detached
// (they are observations for it); the full flow keeps the rigid flow's gradient, so in the paper's
// joint stage 2 the flow losses also train depth and pose.
// `teacher` (Networks::frozen_depth_copy of the weights the stage started from): with
// stage.weights.anchor > 0, the depth anchor (losses/depth_anchor.h) on the target's finest scale.
StepOutput compute_losses(Networks& nets, const torch::Tensor& tgt, const torch::Tensor& srcs, const torch::Tensor& K,
                          const StageConfig& stage, const Config& config, DepthNet teacher = nullptr);

}  // namespace geo
