#include "train/validate.h"

#include "data/loader.h"

namespace geo {

Validation validate(Networks& nets, std::shared_ptr<const SnippetSource> source, const StageConfig& stage,
                    const Config& config, const torch::Device& device, const std::function<bool()>& stop) {
  torch::NoGradGuard no_grad;
  nets.depth->eval();
  nets.pose->eval();
  if (nets.flow) nets.flow->eval();
  LoaderOptions lo;
  lo.batch_size = stage.batch_size;
  lo.workers = 0;
  lo.shuffle = false;
  lo.skip_bad = config.data.on_bad_sample == BadSample::kSkip;
  lo.augment.enabled = false;
  Validation v;
  v.snippets = source->size();
  BatchLoader loader(std::move(source), lo);
  const int64_t batches = (static_cast<int64_t>(v.snippets) + lo.batch_size - 1) / lo.batch_size;
  const bool flow = stage.uses_flow();
  double rigid = 0, flow_sum = 0;
  for (int64_t k = 0; k < batches; ++k) {
    if (stop && stop()) {
      v.interrupted = true;
      break;
    }
    Batch b = loader.next();
    const auto out = compute_losses(nets, b.tgt.to(device), b.srcs.to(device), b.K.to(device), stage, config);
    rigid += out.losses.rigid.item<double>();
    if (flow) flow_sum += out.losses.flow.item<double>();
  }
  nets.set_modes(stage);
  if (v.interrupted) return v;
  const double n = static_cast<double>(std::max<int64_t>(batches, 1));
  v.rigid = rigid / n;
  if (flow) v.flow = flow_sum / n;
  const bool rigid_trained = stage.trains(Net::kDepth) || stage.trains(Net::kPose);
  v.score = (rigid_trained ? v.rigid : 0.0) + (flow ? *v.flow : 0.0);
  return v;
}

}  // namespace geo
