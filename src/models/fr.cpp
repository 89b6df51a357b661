#include "models/fr.h"

#include <algorithm>

namespace geo {

FeatureRefinementImpl::FeatureRefinementImpl(const FeatureRefinementOptions& o) : options(o) {
  TORCH_CHECK(o.channels >= 1 && o.ratio >= 1, "FR needs channels >= 1 and ratio >= 1, got ",
              o.channels, " and ", o.ratio);
  const int64_t hidden = std::max(o.min_hidden, o.channels / o.ratio);
  // The shared MLP as 1x1 convolutions without bias (as in common CBAM implementations).
  mlp_in = register_module("mlp_in",
                           torch::nn::Conv2d(torch::nn::Conv2dOptions(o.channels, hidden, 1).bias(false)));
  mlp_out = register_module("mlp_out",
                            torch::nn::Conv2d(torch::nn::Conv2dOptions(hidden, o.channels, 1).bias(false)));
  spatial = register_module(
      "spatial", torch::nn::Conv2d(torch::nn::Conv2dOptions(2, 1, o.kernel).padding(o.kernel / 2).bias(false)));
  if (o.spatial_bn) spatial_bn = register_module("spatial_bn", torch::nn::BatchNorm2d(1));
}

torch::Tensor FeatureRefinementImpl::channel_gate(const torch::Tensor& x) {
  TORCH_CHECK(x.dim() == 4 && x.size(1) == options.channels, "FR input must be [B,",
              options.channels, ",H,W], got ", x.sizes());
  auto mlp = [this](const torch::Tensor& t) { return mlp_out(torch::relu(mlp_in(t))); };
  const auto avg = x.mean({2, 3}, /*keepdim=*/true);
  const auto mx = x.amax({2, 3}, /*keepdim=*/true);
  return torch::sigmoid(mlp(avg) + mlp(mx));
}

torch::Tensor FeatureRefinementImpl::spatial_gate(const torch::Tensor& f1) {
  const auto pooled = torch::cat({f1.amax(1, true), f1.mean(1, true)}, 1);
  auto a = spatial(pooled);
  if (options.spatial_bn) a = spatial_bn(a);
  return torch::sigmoid(a);
}

torch::Tensor FeatureRefinementImpl::forward(const torch::Tensor& x) {
  const auto f1 = x * channel_gate(x);
  return f1 * spatial_gate(f1);
}

}  // namespace geo
