// The three networks of the paper and one training/inference forward pass over a batch:
// DepthNet on every frame, PoseNet on the snippet, rigid losses, then (when the stage trains flow)
// the residual FlowNet in both directions for every source and the flow losses (reference.md
// Sec. 1-3). LibTorch only.
#pragma once

#include "core/config.h"
#include "losses/total_loss.h"
#include "models/depth_net.h"
#include "models/flow_net.h"
#include "models/pose_net.h"

#include <optional>
#include <string>
#include <vector>

namespace geo {

struct Networks {
  DepthNet depth{nullptr};
  PoseNet pose{nullptr};
  FlowNet flow{nullptr};  // null when no stage of the config trains flow

  // Built from the model config; flow only when `with_flow`.
  static Networks create(const Config& config, bool with_flow);
  void to(const torch::Device& device);
  // Trainable networks in train mode; frozen ones in eval mode (BatchNorm statistics fixed, GeoNet).
  void set_modes(const StageConfig& stage);
  std::vector<torch::Tensor> parameters_of(const StageConfig& stage) const;
  // Checkpoint I/O: one nested archive per network ("depth", "pose", "flow"). Loading is strict per
  // network; a network absent from the archive is an error unless `allow_missing_flow` and it is flow.
  void save(torch::serialize::OutputArchive& archive) const;
  void load(torch::serialize::InputArchive& archive, const std::string& source, bool allow_missing_flow);
};

struct StepOutput {
  LossTerms losses;
  std::vector<torch::Tensor> tgt_disp;  // target disparity per scale
  RigidTerms rigid;
  std::optional<FlowTerms> flow;
  PerSourceScale<torch::Tensor> fwd_full;  // full flows (residual + rigid), when flow ran
};

// tgt [B,3,H,W], srcs [B,N,3,H,W], K [B,3,3] on the networks' device. FlowNet inputs are detached
// (they are observations for it); the full flow keeps the rigid flow's gradient, so in the paper's
// joint stage 2 the flow losses also train depth and pose.
StepOutput compute_losses(Networks& nets, const torch::Tensor& tgt, const torch::Tensor& srcs,
                          const torch::Tensor& K, const StageConfig& stage, const Config& config);

}  // namespace geo
