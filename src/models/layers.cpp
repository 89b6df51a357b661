#include "models/layers.h"

#include "models/conv.h"
#include "models/sync_batch_norm.h"

namespace geo {

torch::Tensor upsample2(const torch::Tensor& x, UpsampleMode mode) {
  namespace F = torch::nn::functional;
  auto opts = F::InterpolateFuncOptions().scale_factor(std::vector<double>{2.0, 2.0});
  if (mode == UpsampleMode::kBilinear) return F::interpolate(x, opts.mode(torch::kBilinear).align_corners(false));
  return F::interpolate(x, opts.mode(torch::kNearest));
}

torch::Tensor resize_like(const torch::Tensor& x, const torch::Tensor& ref) {
  if (x.size(2) == ref.size(2) && x.size(3) == ref.size(3)) return x;
  namespace F = torch::nn::functional;
  return F::interpolate(
      x, F::InterpolateFuncOptions().size(std::vector<int64_t>{ref.size(2), ref.size(3)}).mode(torch::kNearest));
}

void init_weights(torch::nn::Module& module) {
  if (UninitialisedWeights::active()) return;  // every weight is read from a file next
  torch::NoGradGuard no_grad;
  for (auto& m : module.modules(/*include_self=*/false)) {  // also callable from constructors
    if (auto* conv = m->as<torch::nn::Conv2dImpl>()) {
      torch::nn::init::xavier_uniform_(conv->weight);
      if (conv->bias.defined()) conv->bias.zero_();
    } else if (auto* bn = m->as<SyncBatchNorm2d>()) {
      bn->weight.fill_(1);
      bn->bias.zero_();
    }
  }
}

void set_batchnorm_style(torch::nn::Module& module, double eps, double momentum) {
  for (auto& m : module.modules(/*include_self=*/true))
    if (auto* bn = m->as<SyncBatchNorm2d>()) bn->options.eps(eps).momentum(momentum);
}

std::vector<torch::Tensor> batchnorm_scales(const torch::nn::Module& module) {
  std::vector<torch::Tensor> out;
  for (const auto& m : module.modules(/*include_self=*/true))
    if (const auto* bn = m->as<SyncBatchNorm2d>())
      if (bn->weight.defined()) out.push_back(bn->weight);
  return out;
}

int64_t count_parameters(const torch::nn::Module& module) {
  int64_t n = 0;
  for (const auto& p : module.parameters()) n += p.numel();
  return n;
}

torch::Tensor normalize_image(const torch::Tensor& image) { return image * 2 - 1; }

}  // namespace geo
