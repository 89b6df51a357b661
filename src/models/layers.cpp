#include "models/layers.h"

#include <array>

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
  torch::Tensor y;
  if (folded()) {
    TORCH_CHECK(!is_training(), "ConvBn: BatchNorm was folded for inference; this module cannot train");
    const auto& o = conv->options;
    const auto k = *o.kernel_size();
    y = torch::conv2d(x, folded_weight_, folded_bias_, o.stride(), {k[0] / 2, k[1] / 2});  // as constructed
  } else {
    y = bn(conv(x));
  }
  return relu ? torch::relu(y) : y;
}

torch::Tensor ConvBnImpl::forward_upsampled(const torch::Tensor& x) {
  const auto& o = conv->options;
  TORCH_CHECK((*o.kernel_size())[0] == 3 && (*o.kernel_size())[1] == 3 && (*o.stride())[0] == 1 &&
                  (*o.stride())[1] == 1,
              "forward_upsampled needs a 3x3 stride-1 ConvBn");
  torch::Tensor y;
  if (folded()) {
    TORCH_CHECK(!is_training(), "ConvBn: BatchNorm was folded for inference; this module cannot train");
    y = conv3x3_of_upsampled(x, folded_weight_, folded_bias_);
  } else {
    y = bn(conv3x3_of_upsampled(x, conv->weight, conv->bias));
  }
  return relu ? torch::relu(y) : y;
}

torch::Tensor conv3x3_of_upsampled(const torch::Tensor& x, const torch::Tensor& weight, const torch::Tensor& bias) {
  TORCH_CHECK(x.dim() == 4 && weight.dim() == 4 && weight.size(2) == 3 && weight.size(3) == 3 &&
                  weight.size(1) == x.size(1),
              "conv3x3_of_upsampled: x ", x.sizes(), " and weight ", weight.sizes(), " do not match");
  // Phase kernels along one spatial dim: phase 0 taps (w0, w1 + w2) at offsets (-1, 0),
  // phase 1 taps (w0 + w1, w2) at offsets (0, +1).
  auto phases = [](const torch::Tensor& w, int64_t dim) {
    const auto w0 = w.select(dim, 0), w1 = w.select(dim, 1), w2 = w.select(dim, 2);
    return std::array<torch::Tensor, 2>{torch::stack({w0, w1 + w2}, dim), torch::stack({w0 + w1, w2}, dim)};
  };
  const auto rows = phases(weight, 2);
  std::vector<torch::Tensor> kernels;  // phase p = 2a + b
  for (int a = 0; a < 2; ++a) {
    const auto cols = phases(rows[a], 3);
    kernels.push_back(cols[0]);
    kernels.push_back(cols[1]);
  }
  const int64_t B = x.size(0), Co = weight.size(0), h = x.size(2), w = x.size(3);
  const auto b4 = bias.defined() ? bias.repeat({4}) : bias;
  // With padding 1 a 2x2 kernel gives (h+1)x(w+1) outputs; output r reads input rows r-1, r.
  // Phase a = 0 needs rows (i-1, i): r = i; phase a = 1 needs (i, i+1): r = i + 1.
  const auto y = torch::conv2d(x, torch::cat(kernels, 0), b4, 1, 1).view({B, 2, 2, Co, h + 1, w + 1});
  auto out = torch::empty({B, Co, h, 2, w, 2}, y.options());
  for (int64_t a = 0; a < 2; ++a)
    for (int64_t b = 0; b < 2; ++b)
      out.select(5, b).select(3, a).copy_(y.select(1, a).select(1, b).narrow(2, a, h).narrow(3, b, w));
  return out.view({B, Co, 2 * h, 2 * w});
}

void ConvBnImpl::fold_batchnorm() {
  if (folded()) return;
  torch::NoGradGuard no_grad;
  const auto scale = bn->weight / torch::sqrt(bn->running_var + bn->options.eps());
  folded_weight_ = (conv->weight * scale.view({-1, 1, 1, 1})).contiguous();
  folded_bias_ = bn->bias - bn->running_mean * scale;
}

int fold_batchnorm(torch::nn::Module& module) {
  int n = 0;
  for (auto& m : module.modules(/*include_self=*/true)) {
    if (auto* cb = m->as<ConvBnImpl>()) {
      cb->fold_batchnorm();
      ++n;
    }
  }
  return n;
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
