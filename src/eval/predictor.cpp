#include "eval/predictor.h"

#include "geometry/pose.h"
#include "core/runtime.h"
#include "core/state_io.h"
#include "train/checkpoints.h"

#include <filesystem>

namespace fs = std::filesystem;

namespace geo {
namespace {

torch::Device choose(const std::string& name) { return select_device(name.empty() ? "auto" : name); }

}  // namespace

Predictor::Predictor(const std::string& checkpoint, const std::string& device)
    : path_(resolve_checkpoint(checkpoint)), device_(choose(device)) {
  auto a = open_archive(path_);
  auto config = checkpoint_config(a, path_);
  if (!config) throw std::runtime_error(path_ + ": checkpoint has no config (not written by geo_train?)");
  config_ = *config;
  torch::serialize::InputArchive flow;
  nets_ = Networks::create(config_, a.try_read("flow", flow));
  nets_.load(a, path_, false);
  nets_.to(device_);
  nets_.prepare_inference();
}

Predictor::Predictor(const Config& config, const std::string& device)
    : config_(config), path_("untrained (" + config.run.name + ", seed " + std::to_string(config.run.seed) + ")"),
      device_(choose(device)) {
  torch::manual_seed(static_cast<uint64_t>(config.run.seed));
  nets_ = Networks::create(config_, true);
  nets_.to(device_);
  nets_.prepare_inference();
}

torch::Tensor Predictor::depth(const torch::Tensor& image) {
  torch::NoGradGuard no_grad;
  return 1.0 / nets_.depth->forward(image.to(device_)).disp[0];
}

torch::Tensor Predictor::pose(const torch::Tensor& tgt, const std::vector<torch::Tensor>& srcs) {
  torch::NoGradGuard no_grad;
  std::vector<torch::Tensor> s;
  for (const auto& x : srcs) s.push_back(x.to(device_));
  const auto vec = nets_.pose->forward(tgt.to(device_), s);  // [B,N,6]
  const int64_t B = vec.size(0), N = vec.size(1);
  return pose_vec_to_matrix(vec.reshape({B * N, 6})).view({B, N, 4, 4});
}

torch::Tensor Predictor::flow(const torch::Tensor& tgt, const torch::Tensor& src, const torch::Tensor& K,
                              const torch::Tensor& prev) {
  torch::NoGradGuard no_grad;
  return predict_pair(nets_, tgt.to(device_), src.to(device_), K.to(device_), config_.loss,
                      prev.defined() ? prev.to(device_) : prev).flow;
}

std::string latest_run_checkpoint(const std::string& runs_dir) {
  if (!fs::is_directory(runs_dir)) return "";
  std::string best;
  fs::file_time_type newest{};
  for (const auto& e : fs::directory_iterator(runs_dir)) {
    const auto latest = e.path() / "checkpoints" / "latest";
    if (!fs::exists(latest)) continue;
    const auto t = fs::last_write_time(latest);
    if (best.empty() || t > newest) {
      newest = t;
      best = e.path().string();
    }
  }
  return best.empty() ? "" : resolve_checkpoint(best);
}

}  // namespace geo
