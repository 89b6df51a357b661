// The pipeline layer's networks: what a set of trained networks is (NetworkSpec), the three networks
// of the paper built from it (Networks), and inference of one pair (predict_pair). Training
// (src/train), evaluation (src/eval) and the library (include/geo/geo.h) sit on top of this layer;
// it knows nothing of optimisers, data or training schedules. LibTorch only.
#pragma once

#include "core/config.h"
#include "core/cuda_graph.h"
#include "models/depth_net.h"
#include "models/flow_net.h"
#include "models/pose_net.h"

#include <memory>
#include <string>
#include <vector>

namespace geo {

// The loss settings the FlowNet's input depends on: its error channel is the photometric error of
// the rigid warp, computed in the loss's image range with its sampler (as in training).
struct FlowInputSettings {
  double ssim_alpha = 0.85;
  std::vector<double> image_range = {-1.0, 1.0};
  Sampler sampler = Sampler::kZeros;

  static FlowInputSettings of(const LossConfig& loss);
  LossConfig as_loss_config() const;  // a LossConfig with these three settings (others default)
};

// What a checkpoint needs to be used, and nothing of training: the architecture (model.*: encoder
// depth, FR switches, BatchNorm style, ...), the input size and sequence length, and the FlowNet
// input's settings. Stored as YAML in exported model files (config keys, so it reads like a config).
struct NetworkSpec {
  ModelConfig model;
  int64_t height = 128, width = 416;  // network input size (data.height, data.width)
  int64_t seq_length = 3;             // frames the PoseNet takes (data.seq_length)
  FlowInputSettings flow_input;       // loss.ssim_alpha, loss.image_range, loss.sampler

  static NetworkSpec of(const Config& config);
  // YAML with the config keys model.*, data.{height,width,seq_length}, loss.{ssim_alpha,...}.
  std::string to_yaml() const;
  // Parses that YAML (or a whole config: the other keys are ignored); errors name `source`.
  static NetworkSpec parse(const std::string& yaml, const std::string& source);
};

// The settings that decide the networks' weight shapes (model.encoder_depth, FR switches, ...,
// data.seq_length) where `trained` and `wanted` differ, as "key A (wanted B), ..."; "" when the
// weights of one fit the networks of the other.
std::string architecture_difference(const NetworkSpec& trained, const NetworkSpec& wanted);

// The one mapping from the model settings to the networks' option structs (models see no Config).
DepthNetOptions depth_net_options(const ModelConfig& model);
FlowNetOptions flow_net_options(const ModelConfig& model);
PoseNetOptions pose_net_options(const NetworkSpec& spec);

struct Networks {
  DepthNet depth{nullptr};
  PoseNet pose{nullptr};
  FlowNet flow{nullptr};  // null when no stage of the config trains flow
  NetworkSpec spec;       // what they were built from

  // Built from the spec (BatchNorm eps/momentum/scale included); flow only when `with_flow`.
  static Networks create(const NetworkSpec& spec, bool with_flow);
  void to(const torch::Device& device);
  // Trainable networks in train mode; frozen ones in eval mode (BatchNorm statistics fixed, GeoNet);
  // with stage.freeze_batch_norm every BatchNorm in eval mode.
  void set_modes(const StageConfig& stage);
  // requires_grad on: the parameters of the networks the stage trains, BatchNorm scales only when
  // spec.model.bn_scale (GeoNet: no gamma). Call once per stage, before building the optimizer.
  void set_trainable(const StageConfig& stage);
  // A copy of the DepthNet's weights and statistics, on its device, in eval mode and without
  // gradients (the depth anchor's teacher: losses/depth_anchor.h).
  DepthNet frozen_depth_copy() const;
  // The parameters that require gradients (what set_trainable selected), in a fixed order.
  std::vector<torch::Tensor> trainable_parameters() const;
  // Inference: every network in eval mode and, with `fold`, BatchNorm folded into the convolutions
  // (ConvBnImpl::fold_batchnorm; same outputs up to rounding, fewer passes over memory). Call after
  // loading and moving to the device; folded networks refuse to train.
  // `bf16`: weights and arithmetic in bfloat16 (inputs cast, outputs float32): faster on CPUs
  // with AVX512-BF16 or AMX and on GPUs; the accuracy against float32 is in tests/api.
  void prepare_inference(bool fold = true, bool bf16 = false);
};

// Inference of one pair, without losses (what geo_eval, geo_infer and geo_bench's pipeline run):
// DepthNet on the target only, the PoseNet on the snippet (tgt, tgt, src) for a 3-frame model
// (zero motion before the target, the pair after it; a 5-frame model sees (tgt, tgt, tgt, src, src)),
// the rigid flow tgt -> src at full resolution, and, when a FlowNet exists, its residual added (its
// input built with nets.spec.flow_input, as in training).
// tgt, src [B,3,H,W], K [B,3,3] on the networks' device (undefined: the PoseNet's learned camera,
// for models with model.learn_intrinsics); call under NoGradGuard/InferenceMode.
// The FlowNet's input for the pair tgt <- src (both [B,3,H,W] in [0,1]) from the rigid step at full
// scale: the rigid flow tgt -> src, the source warped by it and the L2 norm over colour channels of
// the warp's photometric error (loss range; pass the warp and the per-channel error when at hand, as
// rigid_terms keeps them, else they are computed here with rigid_view). keep_gradient: the input carries the rigid step's
// gradient (GeoNet's graph, loss.flow_input_gradient); else it is computed without.
// Training (compute_losses) and inference (predict_pair) both feed the FlowNet this.
torch::Tensor rigid_flow_net_input(const torch::Tensor& tgt, const torch::Tensor& src, const torch::Tensor& rigid_flow,
                                   const LossConfig& loss, torch::Tensor warped = {}, torch::Tensor error_channels = {},
                                   bool keep_gradient = false);

struct PairPrediction {
  torch::Tensor disp;          // [B,1,H,W] target disparity
  torch::Tensor src_from_tgt;  // [B,4,4]
  torch::Tensor rigid_flow;    // [B,2,H,W]
  torch::Tensor flow;          // [B,2,H,W] full flow (= rigid_flow without a FlowNet)
  torch::Tensor K;             // [B,3,3] the camera used: the given one, else the learned one
};
// `prev` (optional): the frame before tgt; the PoseNet then sees (prev.., tgt, src..) instead of
// repeating tgt before it.
PairPrediction predict_pair(Networks& nets, const torch::Tensor& tgt, const torch::Tensor& src, const torch::Tensor& K,
                            const torch::Tensor& prev = {});

// predict_pair (with a given camera) as one CUDA graph (core/cuda_graph.h): its first two calls
// run eagerly, the third captures it, later calls of the same shapes replay it. What it returns is
// overwritten by the next call. Throws where this build has no CUDA.
class GraphedPairPredictor {
 public:
  GraphedPairPredictor(Networks& nets, const torch::Device& device);
  ~GraphedPairPredictor();
  PairPrediction operator()(const torch::Tensor& tgt, const torch::Tensor& src, const torch::Tensor& K);

 private:
  std::unique_ptr<CudaGraphCall> graph_;
};

}  // namespace geo
