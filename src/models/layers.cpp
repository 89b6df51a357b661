#include "models/layers.h"

#include <torch/autograd.h>
#include <torch/version.h>

#include "core/runtime.h"

namespace geo {

ConvBnImpl::ConvBnImpl(int64_t in, int64_t out, int64_t kernel, int64_t stride, bool relu_)
    : relu(relu_) {
  conv = register_module("conv", Conv2d(torch::nn::Conv2dOptions(in, out, kernel)
                                                       .stride(stride)
                                                       .padding(kernel / 2)
                                                       .bias(false)));
  bn = register_module("bn", torch::nn::BatchNorm2d(out));
}

torch::Tensor ConvBnImpl::conv_bn_relu(const torch::Tensor& x, const ConvFn& conv_fn) {
  torch::Tensor y;
  if (folded()) {
    TORCH_CHECK(!is_training(), "ConvBn: BatchNorm was folded for inference; this module cannot train");
    y = conv_fn(x, folded_weight_, folded_bias_);
  } else {
    const auto c = conv_fn(x, conv->weight, conv->bias);
    y = sync && is_training() ? sync_batch_norm(c, *bn, sync) : bn(c);
  }
  return relu ? torch::relu(y) : y;
}

namespace {

// [4*Co, Ci, 2, 2] phase kernels of a [Co, Ci, 3, 3] kernel; the phases' outputs interleaved
// (conv3x3_of_upsampled, below).
torch::Tensor phase_kernels(const torch::Tensor& weight);
torch::Tensor interleave_phases(const torch::Tensor& phases);

// A convolution with kernels prepacked by at::mkldnn_reorder_conv2d_weight: the activations are
// reordered into oneDNN's layout and back, the weights not.
torch::Tensor packed_conv(const torch::Tensor& x, const torch::Tensor& weight, const torch::Tensor& bias,
                          torch::IntArrayRef padding, torch::IntArrayRef stride) {
  return at::mkldnn_convolution(x.contiguous().to_mkldnn(), weight, bias, padding, stride, {1, 1}, 1).to_dense();
}

}  // namespace


bool ConvBnImpl::uses_packed(const torch::Tensor& x, const torch::Tensor& packed) const {
  if (!packed.defined() || !x.device().is_cpu() || x.scalar_type() != folded_weight_.scalar_type()) return false;
  TORCH_CHECK(!is_training(), "ConvBn: BatchNorm was folded for inference; this module cannot train");
  return true;
}

torch::Tensor ConvBnImpl::forward(const torch::Tensor& x) {
  const auto& o = conv->options;
  const auto k = *o.kernel_size();
  const int64_t pad = onednn_channel_padding(x);
  if (uses_packed(x, packed_weight_)) {  // (packed with the padded channels)
    const auto y = packed_conv(pad_channels(x, pad), packed_weight_, packed_bias_, {k[0] / 2, k[1] / 2}, *o.stride());
    return relu ? torch::relu(y) : y;
  }
  return conv_bn_relu(x, [&](const torch::Tensor& in, const torch::Tensor& w, const torch::Tensor& b) {
    return conv2d(in, w, b, *o.stride(), {k[0] / 2, k[1] / 2});  // padding as constructed
  });
}

torch::Tensor ConvBnImpl::forward_upsampled(const torch::Tensor& x) {
  const auto& o = conv->options;
  TORCH_CHECK((*o.kernel_size())[0] == 3 && (*o.kernel_size())[1] == 3 && (*o.stride())[0] == 1 &&
                  (*o.stride())[1] == 1,
              "forward_upsampled needs a 3x3 stride-1 ConvBn");
  if (x.size(2) * x.size(3) < kMinSubpixelArea) return forward(upsample2(x, UpsampleMode::kNearest));
  if (uses_packed(x, packed_phase_weight_)) {
    const int64_t B = x.size(0), Co = folded_weight_.size(0), h = x.size(2), w = x.size(3);
    const auto y = interleave_phases(
        packed_conv(x, packed_phase_weight_, packed_phase_bias_, {1, 1}, {1, 1}).view({B, 2, 2, Co, h + 1, w + 1}));
    return relu ? torch::relu(y) : y;
  }
  return conv_bn_relu(x, conv3x3_of_upsampled);
}

namespace {

// [16, 9]: row (a, b, u, v) = phase (a, b), tap (u, v) of the 2x2 phase kernel; column (k, l) = tap
// of the 3x3 kernel. Along one dim, phase 0 has taps (w0, w1 + w2), phase 1 (w0 + w1, w2).
torch::Tensor phase_matrix(const torch::TensorOptions& options) {
  static const float P[2][2][3] = {{{1, 0, 0}, {0, 1, 1}}, {{1, 1, 0}, {0, 0, 1}}};
  auto m = torch::zeros({16, 9}, torch::kFloat32);
  auto acc = m.accessor<float, 2>();
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b)
      for (int u = 0; u < 2; ++u)
        for (int v = 0; v < 2; ++v)
          for (int k = 0; k < 3; ++k)
            for (int l = 0; l < 3; ++l) acc[((a * 2 + b) * 2 + u) * 2 + v][k * 3 + l] = P[a][u][k] * P[b][v][l];
  return m.to(options);
}

// y [B,2,2,Co,h+1,w+1] (phase (a, b) of output pixel (2i+a, 2j+b) at y[:, a, b, :, i+a, j+b])
// -> [B,Co,2h,2w]. Written as one autograd node: its backward copies the four windows into one
// gradient buffer (slicing y with select/narrow instead costs a zero-filled y-sized buffer and an
// addition per phase in the backward pass).
struct InterleavePhases : torch::autograd::Function<InterleavePhases> {
  static void copy_windows(const torch::Tensor& phases, const torch::Tensor& image6, int64_t h, int64_t w,
                           bool to_image) {
    for (int64_t a = 0; a < 2; ++a)
      for (int64_t b = 0; b < 2; ++b) {
        auto window = phases.select(1, a).select(1, b).narrow(2, a, h).narrow(3, b, w);
        auto pixels = image6.select(5, b).select(3, a);
        if (to_image) pixels.copy_(window); else window.copy_(pixels);
      }
  }
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& y) {
    const int64_t B = y.size(0), Co = y.size(3), h = y.size(4) - 1, w = y.size(5) - 1;
    ctx->saved_data["shape"] = y.sizes().vec();
    auto out = torch::empty({B, Co, h, 2, w, 2}, y.options());
    copy_windows(y, out, h, w, /*to_image=*/true);
    return out.view({B, Co, 2 * h, 2 * w});
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto shape = ctx->saved_data["shape"].toIntVector();
    const int64_t B = shape[0], Co = shape[3], h = shape[4] - 1, w = shape[5] - 1;
    const auto g = grads[0].contiguous().view({B, Co, h, 2, w, 2});
    auto gy = torch::empty(shape, g.options());
    copy_windows(gy, g, h, w, /*to_image=*/false);
    for (int64_t a = 0; a < 2; ++a)  // the row and column each phase does not use
      for (int64_t b = 0; b < 2; ++b) {
        auto p = gy.select(1, a).select(1, b);
        p.select(2, a == 0 ? h : 0).zero_();
        p.select(3, b == 0 ? w : 0).zero_();
      }
    return {gy};
  }
};

}  // namespace

namespace {

torch::Tensor phase_kernels(const torch::Tensor& weight) {
  const int64_t Co = weight.size(0), Ci = weight.size(1);
  // The four 2x2 phase kernels as one matrix product (backward: one small GEMM, not a
  // zero-filled weight-sized buffer per selected tap): [Co*Ci, 9] x [9, 16] -> [4*Co, Ci, 2, 2].
  return weight.reshape({Co * Ci, 9})
      .matmul(phase_matrix(weight.options()).t())
      .view({Co, Ci, 4, 2, 2})
      .permute({2, 0, 1, 3, 4})
      .reshape({4 * Co, Ci, 2, 2});
}

torch::Tensor interleave_phases(const torch::Tensor& phases) { return InterleavePhases::apply(phases); }

}  // namespace

torch::Tensor conv3x3_of_upsampled(const torch::Tensor& x, const torch::Tensor& weight, const torch::Tensor& bias) {
  TORCH_CHECK(x.dim() == 4 && weight.dim() == 4 && weight.size(2) == 3 && weight.size(3) == 3 &&
                  weight.size(1) == x.size(1),
              "conv3x3_of_upsampled: x ", x.sizes(), " and weight ", weight.sizes(), " do not match");
  const int64_t B = x.size(0), Co = weight.size(0), h = x.size(2), w = x.size(3);
  const auto kernels = phase_kernels(weight);
  const auto b4 = bias.defined() ? bias.repeat({4}) : bias;
  // With padding 1 a 2x2 kernel gives (h+1)x(w+1) outputs; output r reads input rows r-1, r.
  // Phase a = 0 needs rows (i-1, i): r = i; phase a = 1 needs (i, i+1): r = i + 1.
  const auto y = conv2d(x, kernels, b4, {1, 1}, {1, 1}).view({B, 2, 2, Co, h + 1, w + 1});
  return interleave_phases(y);
}

namespace {

// The reduction, held by the autograd graph (an opaque capsule in the node's saved data).
struct SumHolder : torch::CustomClassHolder {
  explicit SumHolder(std::shared_ptr<const SumAcrossProcesses> f) : fn(std::move(f)) {}
  std::shared_ptr<const SumAcrossProcesses> fn;
};

// y = x_hat * gamma + beta with x_hat = (x - mean) * invstd; mean and invstd are the statistics over
// all processes (computed before, without autograd); backward accounts for their dependence on x.
struct SyncBatchNormFn : torch::autograd::Function<SyncBatchNormFn> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x, const torch::Tensor& weight,
                               const torch::Tensor& bias, const torch::Tensor& mean, const torch::Tensor& invstd,
                               double count, const std::shared_ptr<const SumAcrossProcesses>& sum) {
    ctx->save_for_backward({x, weight, mean, invstd});
    ctx->saved_data["count"] = count;
    ctx->saved_data["sum"] = c10::IValue::make_capsule(c10::make_intrusive<SumHolder>(sum));
    const auto xf = x.to(torch::kFloat32);
    return ((xf - mean.view({1, -1, 1, 1})) * (invstd * weight.to(torch::kFloat32)).view({1, -1, 1, 1}) +
            bias.to(torch::kFloat32).view({1, -1, 1, 1}))
        .to(x.scalar_type());
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const auto& x = saved[0];
    const auto w = saved[1].to(torch::kFloat32), mean = saved[2], invstd = saved[3];
    const double count = ctx->saved_data["count"].toDouble();
    const auto capsule = ctx->saved_data["sum"].toCapsule();  // keeps the holder alive while in use
    const SumAcrossProcesses& sum = *static_cast<const SumHolder*>(capsule.get())->fn;
    const auto dy = grads[0].to(torch::kFloat32);
    const auto x_hat = (x.to(torch::kFloat32) - mean.view({1, -1, 1, 1})) * invstd.view({1, -1, 1, 1});
    const auto sum_dy = dy.sum({0, 2, 3}), sum_dy_xhat = (dy * x_hat).sum({0, 2, 3});
    auto both = torch::cat({sum_dy, sum_dy_xhat});
    sum(both);  // every process, every backward: the collective order stays the same everywhere
    const int64_t C = sum_dy.size(0);
    const auto g_dy = both.narrow(0, 0, C).div(count).view({1, -1, 1, 1});
    const auto g_dy_xhat = both.narrow(0, C, C).div(count).view({1, -1, 1, 1});
    const auto dx = (dy - g_dy - x_hat * g_dy_xhat) * (invstd * w).view({1, -1, 1, 1});
    return {dx.to(x.scalar_type()), sum_dy_xhat.to(saved[1].scalar_type()), sum_dy.to(saved[1].scalar_type()),
            torch::Tensor(), torch::Tensor(), torch::Tensor(), torch::Tensor()};
  }
};

}  // namespace

torch::Tensor sync_batch_norm(const torch::Tensor& x, torch::nn::BatchNorm2dImpl& bn,
                              std::shared_ptr<const SumAcrossProcesses> sum) {
  TORCH_CHECK(sum, "sync_batch_norm: no reduction given");
  TORCH_CHECK(x.dim() == 4 && x.size(1) == bn.options.num_features(), "sync_batch_norm: input ", x.sizes(),
              " for a BatchNorm of ", bn.options.num_features(), " channels");
  const int64_t C = x.size(1);
  torch::Tensor mean, invstd;
  double count = 0;
  {
    torch::NoGradGuard no_grad;
    // Sums in float64: E[x^2] - E[x]^2 over hundreds of thousands of values per channel.
    const auto xf = x.to(torch::kFloat32);
    auto stats = torch::cat({xf.sum({0, 2, 3}, false, torch::kFloat64), (xf * xf).sum({0, 2, 3}, false, torch::kFloat64),
                             torch::full({1}, static_cast<double>(x.numel() / C), xf.options().dtype(torch::kFloat64))});
    (*sum)(stats);
    count = stats[2 * C].item<double>();
    TORCH_CHECK(count > 1, "sync_batch_norm: one value per channel over all processes; BatchNorm needs more");
    const auto mean64 = stats.narrow(0, 0, C) / count;
    const auto var64 = (stats.narrow(0, C, C) / count - mean64 * mean64).clamp_min(0);
    mean = mean64.to(torch::kFloat32);
    const auto var = var64.to(torch::kFloat32);
    invstd = torch::rsqrt(var64 + bn.options.eps()).to(torch::kFloat32);
    const double m = bn.options.momentum().value_or(0.1);
    bn.running_mean.mul_(1 - m).add_(mean.to(bn.running_mean.scalar_type()), m);
    bn.running_var.mul_(1 - m).add_((var * (count / (count - 1))).to(bn.running_var.scalar_type()), m);
    bn.num_batches_tracked.add_(1);
  }
  return SyncBatchNormFn::apply(x, bn.weight, bn.bias, mean, invstd, count, sum);
}

int set_batchnorm_sync(torch::nn::Module& module, std::shared_ptr<const SumAcrossProcesses> sum) {
  int n = 0;
  for (auto& m : module.modules(/*include_self=*/true)) {
    if (auto* cb = m->as<ConvBnImpl>()) {
      cb->sync = sum;
      ++n;
    }
  }
  return n;
}

void ConvBnImpl::fold_batchnorm(torch::Dtype dtype) {
  if (folded()) return;
  torch::NoGradGuard no_grad;
  const auto scale = bn->weight / torch::sqrt(bn->running_var + bn->options.eps());
  const auto weight = conv->weight * scale.view({-1, 1, 1, 1}), bias = bn->bias - bn->running_mean * scale;
  folded_weight_ = weight.to(dtype).contiguous();
  folded_bias_ = bias.to(dtype);
  if (conv->weight.device().is_cpu() && at::hasMKLDNN() && at::globalContext().userEnabledMkldnn())
    prepack(weight, bias.to(torch::kFloat32));  // oneDNN adds a float32 bias to bf16 products
}

void ConvBnImpl::prepack(const torch::Tensor& w32, const torch::Tensor& b32) {
  const auto& o = conv->options;
  const auto k = *o.kernel_size();
  const std::vector<int64_t> pad = {k[0] / 2, k[1] / 2};
  try {
    const auto w = pad_channels(folded_weight_, onednn_channel_padding(folded_weight_));  // as forward pads x
    packed_weight_ = at::mkldnn_reorder_conv2d_weight(w.contiguous().to_mkldnn(), pad, *o.stride(), {1, 1}, 1);
    packed_bias_ = b32;
    if (k[0] == 3 && k[1] == 3 && (*o.stride())[0] == 1 && (*o.stride())[1] == 1) {
      packed_phase_weight_ = at::mkldnn_reorder_conv2d_weight(
          phase_kernels(w32).to(folded_weight_.scalar_type()).contiguous().to_mkldnn(), {1, 1}, {1, 1}, {1, 1}, 1);
      packed_phase_bias_ = b32.repeat({4});
    }
    // A CPU without oneDNN's kernels for this type (bf16 without AVX-512) fails here, not later.
    packed_conv(torch::zeros({1, w.size(1), k[0], k[1]}, folded_weight_.options()), packed_weight_,
                packed_bias_, pad, *o.stride());
  } catch (const c10::Error&) {
    packed_weight_ = packed_phase_weight_ = packed_bias_ = packed_phase_bias_ = torch::Tensor();
  }
}

int fold_batchnorm(torch::nn::Module& module, torch::Dtype dtype) {
  int n = 0;
  for (auto& m : module.modules(/*include_self=*/true)) {
    if (auto* cb = m->as<ConvBnImpl>()) {
      cb->fold_batchnorm(dtype);
      ++n;
    }
  }
  return n;
}

torch::Tensor upsample2(const torch::Tensor& x, UpsampleMode mode) {
  namespace F = torch::nn::functional;
  auto opts = F::InterpolateFuncOptions().scale_factor(std::vector<double>{2.0, 2.0});
  if (mode == UpsampleMode::kBilinear) return F::interpolate(x, opts.mode(torch::kBilinear).align_corners(false));
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
    if (auto* conv = m->as<torch::nn::Conv2dImpl>()) {
      torch::nn::init::xavier_uniform_(conv->weight);
      if (conv->bias.defined()) conv->bias.zero_();
    } else if (auto* bn = m->as<torch::nn::BatchNorm2d>()) {
      bn->weight.fill_(1);
      bn->bias.zero_();
    }
  }
}

void set_batchnorm_style(torch::nn::Module& module, double eps, double momentum) {
  for (auto& m : module.modules(/*include_self=*/true))
    if (auto* bn = m->as<torch::nn::BatchNorm2d>()) bn->options.eps(eps).momentum(momentum);
}

std::vector<torch::Tensor> batchnorm_scales(const torch::nn::Module& module) {
  std::vector<torch::Tensor> out;
  for (const auto& m : module.modules(/*include_self=*/true))
    if (const auto* bn = m->as<torch::nn::BatchNorm2d>())
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
