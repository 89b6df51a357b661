// The one owner of geo's two file formats (LibTorch archives). Nothing else reads or writes their keys.
//
//   training checkpoint (geo_train)     model file (geo_export)
//     depth, pose, [flow]  networks       geo_model_format "geo-model 1"
//     optimizer            Adam state     spec            NetworkSpec as YAML
//     train_state          TrainState     depth, pose, [flow]  networks (fp32 or fp16)
//     config               the run's config as YAML
//     init_configs         the configs the run's initial weights were trained with (optional)
//
//   int8 model file (geo_export --int8): a model file whose networks run in int8 only
//     geo_model_format     "geo-model 3 (int8 kernels, mapped)"
//     depth, pose, [flow]  networks, the kernels of the layers that run in int8 left out (empty)
//     int8_<network>       the calibration: each quantized point's range (models/int8.h)
//   and beside that archive, read where they lie in the file (core/mapped_archive.h):
//     int8_kernels_<network>/<kernel>  those layers' int8 kernels (Int8Graph::kernels)
//   "geo-model 2 (int8 kernels)" files (earlier geo) keep the kernels inside the archive, as a
//   sub-archive int8_kernels_<network>; still read.
//   A model file quantized with its float kernels kept ("geo-model 1") has int8_<network> alone.
//
// Checkpoints written before the typed train state (a float64 "meta" [stage, iteration, best] and a
// separate "world_size") are still read.
//
// Where checkpoints lie in a run folder, and which one a folder stands for: pipeline/run_folder.h.
#pragma once

#include "core/config.h"
#include "core/mapped_archive.h"
#include "pipeline/networks.h"
#include "pipeline/run_folder.h"

#include <torch/torch.h>

#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace geo {

// Where training stands.
struct TrainState {
  int64_t stage = 0;                                            // index into the config's stages
  int64_t iteration = 0;                                        // iterations done in that stage
  double best_score = std::numeric_limits<double>::infinity();  // the stage's best validation score
  int64_t world_size = 1;  // processes of the run that wrote it (train/distributed.h)
  // The validation due at this iteration was interrupted (a signal): a resumed run does it first.
  bool validation_pending = false;
  // The stage holds depth (StageConfig::hold_masked, decided before its first step): a resumed run
  // trains the held stage too.
  bool depth_held = false;
};

// A training checkpoint's contents, written by write_checkpoint. The optimizer is optional (tests,
// tools); networks and config are not.
struct CheckpointContents {
  const Networks& networks;
  const torch::optim::Optimizer* optimizer = nullptr;
  TrainState state;
  const Config& config;
  // The chain of `init` checkpoints the weights started from, nearest first: each one's config as
  // YAML, or "unknown: <why>" for one that carried none (a model file). What the networks have seen
  // besides this run's data (geo_eval's training-drive check follows it).
  std::vector<std::string> init_configs = {};
};
void write_checkpoint(torch::serialize::OutputArchive& archive, const CheckpointContents& contents);
// The train state alone (write_checkpoint's part of it; tests of the run folder's rotation).
void write_train_state(torch::serialize::OutputArchive& archive, const TrainState& state);

// A model file for deployment: the networks' weights (`half`: stored as float16) and their spec;
// written durably to `path`.
void write_model_file(const std::string& path, const Networks& networks, bool half);

// Before writing a model file at `out` from the checkpoint `source`: refuses `out` when it is that
// checkpoint (a run folder's best-<stage>.pt is a hard link to one) or, unless `force`, when it is
// an existing file that is not a geo_export model file (a training checkpoint holds Adam's state and
// the run's config, which a model file does not). Throws naming `label` (e.g. "--out") and why.
void check_model_file_target(const std::string& label, const std::string& out, const std::string& source, bool force);

// A checkpoint or model file opened for reading. Every error names the file.
class CheckpointFile {
 public:
  // Throws "<path>: not a readable geo/LibTorch file ..." for anything LibTorch cannot open.
  explicit CheckpointFile(std::string path);

  const std::string& path() const { return path_; }
  bool is_model_file() const { return model_file_; }  // written by geo_export
  bool has_flow() const { return has_flow_; }         // holds a FlowNet
  // The networks' spec: the model file's, or the one of the training config.
  NetworkSpec spec() const;
  // The training config (training checkpoints), nullopt for model files.
  const std::optional<Config>& config() const { return config_; }
  // CheckpointContents::init_configs as written (empty for model files and older checkpoints).
  const std::vector<std::string>& init_configs() const { return init_configs_; }
  // What a run initialised from this file inherits: its own config (or "unknown: ..." for a model
  // file), then its init_configs.
  std::vector<std::string> lineage() const;
  // Throws "<path>: not a geo training checkpoint ..." for model files and foreign files.
  TrainState train_state();
  // Weights into `nets` (strict per network; a network absent from the file is an error unless
  // `allow_missing_flow` and it is the FlowNet). An int8 model file is refused unless `int8_kernels`
  // (the caller quantizes with int8_kernels next: the kernels it leaves out stay empty until then).
  void load_networks(Networks& nets, bool allow_missing_flow, bool int8_kernels = false);
  // The int8 calibration a geo_export model file keeps for a network ("depth", "flow", "pose"): the range of
  // each quantized point [points,2] (models/int8.h), or nullopt.
  std::optional<torch::Tensor> int8_ranges(const std::string& network);
  // An int8 model file (geo_export --int8): its networks run in int8 only.
  bool is_int8_only() const { return int8_only_; }
  // Its int8 kernels of a network (Int8Graph::kernels); empty for other files.
  std::map<std::string, torch::Tensor> int8_kernels(const std::string& network);
  // Networks created from the file's spec (a FlowNet when it holds one) with its weights.
  Networks networks();
  // The optimizer's state, if the file holds one; returns whether it did.
  bool load_optimizer(torch::optim::Optimizer& optimizer);

 private:
  std::string path_;
  torch::serialize::InputArchive archive_;
  std::optional<MappedTensors> mapped_;  // a container's mapped tensors (int8 model files)
  bool model_file_ = false;
  bool int8_only_ = false;
  bool has_flow_ = false;
  std::optional<Config> config_;
  std::vector<std::string> init_configs_;
  std::optional<NetworkSpec> spec_;
};

}  // namespace geo
