#include "eval/predictor.h"

#include "pipeline/checkpoint.h"

#include <filesystem>

namespace fs = std::filesystem;

namespace geo {

namespace {
LoadOptions on_device(const std::string& device) {
  LoadOptions o;
  o.device = device.empty() ? "auto" : device;
  return o;
}
}  // namespace

Predictor::Predictor(const std::string& checkpoint, const std::string& device)
    : Predictor(checkpoint, on_device(device)) {}

Predictor::Predictor(const std::string& checkpoint, const LoadOptions& options)
    : path_(fs::is_directory(checkpoint) ? resolve_checkpoint(checkpoint) : checkpoint) {
  model_ = Model::load(path_, options);
  const auto& configs = model_->training_configs();
  if (!configs.empty()) training_config_ = parse_config(configs.front(), path_ + " [config]");
}

Predictor::Predictor(const Config& config, const std::string& device) : Predictor(config, on_device(device)) {}

Predictor::Predictor(const Config& config, const LoadOptions& options)
    : path_("untrained (" + config.run.name + ", seed " + std::to_string(config.run.seed) + ")") {
  torch::manual_seed(static_cast<uint64_t>(config.run.seed));
  model_ = Model::create(to_yaml(config), options);
}

std::vector<std::string> Predictor::init_configs() const {
  const auto& configs = model_->training_configs();
  return configs.empty() ? configs : std::vector<std::string>(configs.begin() + 1, configs.end());
}

torch::Tensor Predictor::depth(const torch::Tensor& image) { return model_->depth(image).unsqueeze(1); }

torch::Tensor Predictor::pose(const torch::Tensor& tgt, const std::vector<torch::Tensor>& srcs) {
  // The snippet in time order: the sources before the target, the target, the sources after it.
  std::vector<torch::Tensor> frames(srcs.begin(), srcs.begin() + static_cast<long>(srcs.size() / 2));
  frames.push_back(tgt);
  frames.insert(frames.end(), srcs.begin() + static_cast<long>(srcs.size() / 2), srcs.end());
  return model_->pose(frames);  // [B,N,4,4]
}

Model::FlowParts Predictor::flow(const torch::Tensor& tgt, const torch::Tensor& src, const torch::Tensor& K,
                                 const torch::Tensor& prev) {
  return model_->flow_parts(tgt, src, K, prev);
}

std::string latest_run_checkpoint(const std::string& runs_dir) {
  if (!fs::is_directory(runs_dir)) return "";
  std::string best;
  fs::file_time_type newest{};
  for (const auto& e : fs::directory_iterator(runs_dir)) {
    const RunFolder run(e.path().string());
    if (!fs::exists(run.latest_pointer())) continue;
    const auto t = fs::last_write_time(run.latest_pointer());
    if (best.empty() || t > newest) {
      newest = t;
      best = run.root();
    }
  }
  return best.empty() ? "" : RunFolder(best).resolve();
}

}  // namespace geo
