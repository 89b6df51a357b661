#include "models/layers.h"

namespace geo {

ConvBnImpl::ConvBnImpl(int64_t in, int64_t out, int64_t kernel, int64_t stride, bool relu_)
    : relu(relu_) {
  conv = register_module("conv", torch::nn::Conv2d(torch::nn::Conv2dOptions(in, out, kernel)
                                                       .stride(stride)
                                                       .padding(kernel / 2)
                                                       .bias(false)));
  bn = register_module("bn", torch::nn::BatchNorm2d(out));
}

torch::Tensor ConvBnImpl::forward(const torch::Tensor& x) {
  auto y = bn(conv(x));
  return relu ? torch::relu(y) : y;
}

torch::Tensor upsample2(const torch::Tensor& x, const std::string& mode) {
  namespace F = torch::nn::functional;
  auto opts = F::InterpolateFuncOptions().scale_factor(std::vector<double>{2.0, 2.0});
  if (mode == "bilinear") return F::interpolate(x, opts.mode(torch::kBilinear).align_corners(false));
  TORCH_CHECK(mode == "nearest", "upsample mode must be nearest or bilinear, got '", mode, "'");
  return F::interpolate(x, opts.mode(torch::kNearest));
}

torch::Tensor resize_like(const torch::Tensor& x, const torch::Tensor& ref) {
  if (x.size(2) == ref.size(2) && x.size(3) == ref.size(3)) return x;
  namespace F = torch::nn::functional;
  return F::interpolate(x, F::InterpolateFuncOptions()
                               .size(std::vector<int64_t>{ref.size(2), ref.size(3)})
                               .mode(torch::kNearest));
}

void init_weights(torch::nn::Module& module) {
  torch::NoGradGuard no_grad;
  for (auto& m : module.modules(/*include_self=*/false)) {  // also callable from constructors
    if (auto* conv = m->as<torch::nn::Conv2d>()) {
      torch::nn::init::xavier_uniform_(conv->weight);
      if (conv->bias.defined()) conv->bias.zero_();
    } else if (auto* bn = m->as<torch::nn::BatchNorm2d>()) {
      bn->weight.fill_(1);
      bn->bias.zero_();
    }
  }
}

int64_t count_parameters(const torch::nn::Module& module) {
  int64_t n = 0;
  for (const auto& p : module.parameters()) n += p.numel();
  return n;
}

torch::Tensor normalize_image(const torch::Tensor& image) { return image * 2 - 1; }

}  // namespace geo
