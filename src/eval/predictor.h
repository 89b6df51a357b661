// A trained model loaded from a checkpoint (its config travels inside), for evaluation: depth of an
// image, relative pose of a snippet, full flow of a pair, in the shapes the protocols use. A thin
// layer over geo::Model (include/geo/geo.h), so evaluation scores exactly what the library computes.
// Inputs are RGB in [0,1] at the network's size (config data.height x data.width).
#pragma once

#include "core/config.h"
#include "geo/geo.h"

#include <optional>
#include <string>

namespace geo {

class Predictor {
 public:
  // `checkpoint`: a .pt file or a run folder (its best, else latest checkpoint).
  explicit Predictor(const std::string& checkpoint, const std::string& device = "auto");
  Predictor(const std::string& checkpoint, const LoadOptions& options);  // device, precision, ...
  // An untrained model of this config (seeded with run.seed): the "before training" baseline.
  Predictor(const Config& config, const std::string& device);
  Predictor(const Config& config, const LoadOptions& options);
  int64_t seq_length() const { return model_->spec().seq_length; }
  const std::string& path() const { return path_; }
  int64_t height() const { return model_->spec().height; }
  int64_t width() const { return model_->spec().width; }
  bool has_flow() const { return model_->spec().has_flow; }
  // fp32, bf16 or int8: what the networks compute in (after quantize_int8: int8).
  const std::string& precision() const { return model_->spec().precision; }
  torch::Device device() const { return model_->device(); }
  // The config a training checkpoint carries: what the model was trained on. nullopt for model
  // files (geo_export) and untrained models.
  const std::optional<Config>& training_config() const { return training_config_; }
  // The configs its initial weights were trained with, nearest first ("unknown: ..." where a link
  // carried none): geo::Model::training_configs() after the first.
  std::vector<std::string> init_configs() const;
  // The model in int8 from now on, calibrated on `frames` (geo::Model::quantize_int8).
  void quantize_int8(const std::vector<torch::Tensor>& frames) { model_->quantize_int8(frames); }

  // image [B,3,H,W] -> depth [B,1,H,W] in the network's (unknown) scale: 1 / disparity.
  torch::Tensor depth(const torch::Tensor& image);
  // tgt [B,3,H,W], srcs N x [B,3,H,W] (N = seq_length - 1) -> [B,N,4,4] src_from_tgt.
  torch::Tensor pose(const torch::Tensor& tgt, const std::vector<torch::Tensor>& srcs);
  // Full flow tgt -> src [B,2,H,W] in pixels: rigid flow from depth and pose plus the FlowNet's
  // residual (rigid flow alone when the checkpoint has no FlowNet). The PoseNet sees the snippet
  // (tgt, tgt, src) for a 3-frame model: zero motion before the target, the pair after it.
  // `prev` (optional, [B,3,H,W]): the frame before tgt, for the PoseNet's snippet (prev, tgt, src).
  // `.rigid`: the rigid flow alone (equal to `.full` without a FlowNet).
  Model::FlowParts flow(const torch::Tensor& tgt, const torch::Tensor& src, const torch::Tensor& K,
                        const torch::Tensor& prev = {});

 private:
  std::string path_;
  std::optional<Model> model_;
  std::optional<Config> training_config_;
};

// The most recent run's best checkpoint under `runs_dir` (newest folder with checkpoints), or "".
std::string latest_run_checkpoint(const std::string& runs_dir);

}  // namespace geo
