#include "train/validate.h"

#include "data/loader.h"

#include <algorithm>

namespace geo {

Validation validate(Networks& nets, std::shared_ptr<const SnippetSource> source, const StageConfig& stage,
                    const Config& config, const torch::Device& device, const std::function<bool()>& stop) {
  torch::NoGradGuard no_grad;
  nets.depth->eval();
  nets.pose->eval();
  if (nets.flow) nets.flow->eval();
  LoaderOptions lo = loader_options(config.data, stage.batch_size);
  lo.workers = 0;
  lo.shuffle = false;
  lo.augment.enabled = false;
  Validation v;
  v.snippets = source->size();
  BatchLoader loader(std::move(source), lo);
  const int64_t batches = (static_cast<int64_t>(v.snippets) + lo.batch_size - 1) / lo.batch_size;
  const bool flow = stage.uses_flow();
  double rigid = 0, flow_sum = 0, masked = 0;
  const int64_t total = static_cast<int64_t>(v.snippets);
  for (int64_t k = 0; k < batches; ++k) {
    if (stop && stop()) {
      v.interrupted = true;
      break;
    }
    Batch b = loader.next();
    // The loader fills the last batch from the start of the list again: those repeats are cut, and
    // each batch's mean counts by its snippets, so every snippet weighs the same.
    const int64_t count = std::min<int64_t>(lo.batch_size, total - k * lo.batch_size);
    const auto out = compute_losses(nets, b.tgt.slice(0, 0, count).to(device), b.srcs.slice(0, 0, count).to(device),
                                    b.K.slice(0, 0, count).to(device), stage, config);
    rigid += out.losses.rigid.item<double>() * static_cast<double>(count);
    if (flow) flow_sum += out.losses.flow.item<double>() * static_cast<double>(count);
    if (out.losses.automasked.defined()) masked += out.losses.automasked.item<double>() * static_cast<double>(count);
  }
  nets.set_modes(stage);
  if (v.interrupted) return v;
  const double n = static_cast<double>(std::max<int64_t>(total, 1));
  v.rigid = rigid / n;
  if (flow) v.flow = flow_sum / n;
  if (config.loss.automask) v.automasked = masked / n;
  const bool rigid_trained = stage.trains(Net::kDepth) || stage.trains(Net::kPose);
  v.score = (rigid_trained ? v.rigid : 0.0) + (flow ? *v.flow : 0.0);
  return v;
}

}  // namespace geo
