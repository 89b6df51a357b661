// The three networks of the paper and one training/inference forward pass over a batch:
// DepthNet on every frame, PoseNet on the snippet, rigid losses, then (when the stage trains flow)
// the residual FlowNet in both directions for every source and the flow losses (paper Sec. 3).
// LibTorch only.
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

// The one mapping from the configuration to the networks' option structs (models see no Config).
DepthNetOptions depth_net_options(const ModelConfig& model);
FlowNetOptions flow_net_options(const ModelConfig& model);
PoseNetOptions pose_net_options(const Config& config);

struct Networks {
  DepthNet depth{nullptr};
  PoseNet pose{nullptr};
  FlowNet flow{nullptr};  // null when no stage of the config trains flow
  bool learn_bn_scale = true;  // model.bn_scale: false keeps every BatchNorm gamma at 1 (GeoNet)

  // Built from the model config (BatchNorm eps/momentum/scale included); flow only when `with_flow`.
  static Networks create(const Config& config, bool with_flow);
  void to(const torch::Device& device);
  // Trainable networks in train mode; frozen ones in eval mode (BatchNorm statistics fixed, GeoNet).
  void set_modes(const StageConfig& stage);
  // requires_grad on: the parameters of the networks the stage trains, BatchNorm scales only when
  // learn_bn_scale. Call once per stage, before building the optimizer.
  void set_trainable(const StageConfig& stage);
  // The parameters that require gradients (what set_trainable selected), in a fixed order.
  std::vector<torch::Tensor> trainable_parameters() const;
  // Inference: every network in eval mode and, with `fold`, BatchNorm folded into the convolutions
  // (ConvBnImpl::fold_batchnorm; same outputs up to rounding, fewer passes over memory). Call after
  // loading and moving to the device; folded networks refuse to train.
  // `bf16`: weights and arithmetic in bfloat16 (inputs cast, outputs float32): faster on CPUs
  // with AVX512-BF16 or AMX and on GPUs; the accuracy against float32 is in tests/api.
  void prepare_inference(bool fold = true, bool bf16 = false);
  // Checkpoint I/O: one nested archive per network ("depth", "pose", "flow"). Loading is strict per
  // network; a network absent from the archive is an error unless `allow_missing_flow` and it is flow.
  // `floating`: the type floating-point tensors are stored in (geo_export --half); default as they are.
  void save(torch::serialize::OutputArchive& archive, std::optional<torch::ScalarType> floating = std::nullopt) const;
  void load(torch::serialize::InputArchive& archive, const std::string& source, bool allow_missing_flow);
};

// The settings that decide the networks' weight shapes (model.encoder_depth, FR switches, ...,
// data.seq_length) where `trained` and `wanted` differ, as "key A (wanted B), ..."; "" when the
// weights of one fit the networks of the other.
std::string architecture_difference(const Config& trained, const Config& wanted);

// The config stored in a checkpoint by geo_train, or nullopt for files without one.
std::optional<Config> checkpoint_config(torch::serialize::InputArchive& archive, const std::string& source);

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

// Inference of one pair, without losses (what geo_eval, geo_infer and geo_bench's pipeline run):
// DepthNet on the target only, the PoseNet on the snippet (tgt, tgt, src) for a 3-frame model
// (zero motion before the target, the pair after it; a 5-frame model sees (tgt, tgt, tgt, src, src)),
// the rigid flow tgt -> src at full resolution, and, when a FlowNet exists, its residual added.
// tgt, src [B,3,H,W], K [B,3,3] on the networks' device; call under NoGradGuard/InferenceMode.
struct PairPrediction {
  torch::Tensor disp;          // [B,1,H,W] target disparity
  torch::Tensor src_from_tgt;  // [B,4,4]
  torch::Tensor rigid_flow;    // [B,2,H,W]
  torch::Tensor flow;          // [B,2,H,W] full flow (= rigid_flow without a FlowNet)
};
// `loss` gives what the FlowNet's input depends on: the sampler, the image range and the SSIM weight
// of its error channel (as in training).
// `prev` (optional): the frame before tgt; the PoseNet then sees (prev.., tgt, src..) instead of
// repeating tgt before it.
PairPrediction predict_pair(Networks& nets, const torch::Tensor& tgt, const torch::Tensor& src,
                            const torch::Tensor& K, const LossConfig& loss, const torch::Tensor& prev = {});

}  // namespace geo
