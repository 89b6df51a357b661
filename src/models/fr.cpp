#include "models/fr.h"

#include "core/tensor_checks.h"
#include "models/conv.h"

#include <ATen/Dispatch.h>
#include <ATen/Parallel.h>
#include <torch/autograd.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace geo {

namespace {

// max(a, b) that keeps a NaN, as amax does.
template <typename T>
T nan_max(T a, T b) {
  return (b > a || std::isnan(b)) ? b : a;
}

// x viewed as [outer, len, inner] -> max and mean over `len`, each [outer, inner], in one pass.
// Backward as amax's (and TensorFlow's reduce_max, which CBAM/GeoNet code uses): the gradient of
// the max is shared evenly among tied elements; the mean's is spread over all. Composed of tensor
// ops the same took ~10 full-size passes per FR block (equality mask, its sum, division, products).
struct MaxMeanPool : torch::autograd::Function<MaxMeanPool> {
  static torch::autograd::variable_list forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x_in,
                                                int64_t len, int64_t inner) {
    const auto x = x_in.contiguous();
    const int64_t outer = x.numel() / (len * inner);
    auto mx = torch::empty({outer, inner}, x.options()), mean = torch::empty({outer, inner}, x.options());
    AT_DISPATCH_FLOATING_TYPES(x.scalar_type(), "max_mean_pool", [&] {
      const scalar_t* xp = x.data_ptr<scalar_t>();
      scalar_t *mp = mx.data_ptr<scalar_t>(), *sp = mean.data_ptr<scalar_t>();
      at::parallel_for(0, outer, 1, [&](int64_t begin, int64_t end) {
        for (int64_t o = begin; o < end; ++o) {
          const scalar_t* xo = xp + o * len * inner;
          scalar_t *m = mp + o * inner, *s = sp + o * inner;
          if (inner == 1) {  // one contiguous row: independent accumulators, no loop per element
            constexpr int K = 8;
            scalar_t mk[K];
            double sk[K] = {0};
            std::fill(mk, mk + K, xo[0]);
            int64_t l = 0;
            for (; l + K <= len; l += K)
              for (int k = 0; k < K; ++k) {
                mk[k] = nan_max(mk[k], xo[l + k]);
                sk[k] += xo[l + k];
              }
            for (; l < len; ++l) {
              mk[0] = nan_max(mk[0], xo[l]);
              sk[0] += xo[l];
            }
            scalar_t best = mk[0];
            double sum = 0;
            for (int k = 0; k < K; ++k) {
              best = nan_max(best, mk[k]);
              sum += sk[k];
            }
            *m = best;
            *s = static_cast<scalar_t>(sum / static_cast<double>(len));
            continue;
          }
          std::copy(xo, xo + inner, m);
          std::copy(xo, xo + inner, s);
          for (int64_t l = 1; l < len; ++l) {
            const scalar_t* r = xo + l * inner;
            for (int64_t i = 0; i < inner; ++i) {
              m[i] = nan_max(m[i], r[i]);
              s[i] += r[i];
            }
          }
          for (int64_t i = 0; i < inner; ++i) s[i] /= static_cast<scalar_t>(len);
        }
      });
    });
    ctx->save_for_backward({x, mx});
    ctx->saved_data["len"] = len;
    ctx->saved_data["inner"] = inner;
    return {mx, mean};
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const auto &x = saved[0], &mx = saved[1];
    const int64_t len = ctx->saved_data["len"].toInt(), inner = ctx->saved_data["inner"].toInt();
    const int64_t outer = x.numel() / (len * inner);
    const auto gmax = grads[0].defined() ? grads[0].contiguous() : torch::zeros_like(mx);
    const auto gmean = grads[1].defined() ? grads[1].contiguous() : torch::zeros_like(mx);
    auto gx = torch::empty_like(x);
    AT_DISPATCH_FLOATING_TYPES(x.scalar_type(), "max_mean_pool_backward", [&] {
      const scalar_t *xp = x.data_ptr<scalar_t>(), *mp = mx.data_ptr<scalar_t>();
      const scalar_t *gm = gmax.data_ptr<scalar_t>(), *ga = gmean.data_ptr<scalar_t>();
      scalar_t* gp = gx.data_ptr<scalar_t>();
      at::parallel_for(0, outer, 1, [&](int64_t begin, int64_t end) {
        std::vector<scalar_t> share(inner), even(inner);
        for (int64_t o = begin; o < end; ++o) {
          const scalar_t *xo = xp + o * len * inner, *m = mp + o * inner;
          scalar_t* go = gp + o * len * inner;
          if (inner == 1) {
            int64_t ties = 0;
            for (int64_t l = 0; l < len; ++l) ties += xo[l] == *m;
            const scalar_t sh = ties > 0 ? gm[o] / static_cast<scalar_t>(ties) : scalar_t(0);
            const scalar_t ev = ga[o] / static_cast<scalar_t>(len);
            for (int64_t l = 0; l < len; ++l) go[l] = (xo[l] == *m ? sh : scalar_t(0)) + ev;
            continue;
          }
          std::fill(share.begin(), share.end(), scalar_t(0));
          for (int64_t l = 0; l < len; ++l)
            for (int64_t i = 0; i < inner; ++i) share[i] += xo[l * inner + i] == m[i] ? scalar_t(1) : scalar_t(0);
          for (int64_t i = 0; i < inner; ++i) {
            share[i] = share[i] > 0 ? gm[o * inner + i] / share[i] : scalar_t(0);
            even[i] = ga[o * inner + i] / static_cast<scalar_t>(len);
          }
          for (int64_t l = 0; l < len; ++l)
            for (int64_t i = 0; i < inner; ++i)
              go[l * inner + i] = (xo[l * inner + i] == m[i] ? share[i] : scalar_t(0)) + even[i];
        }
      });
    });
    return {gx, torch::Tensor(), torch::Tensor()};
  }
};

// x in channels-last order and not also in the dense one (inference's activations): pooled where
// it lies, as [B,H,W,C], instead of copied into the dense order first.
bool pooled_channels_last(const torch::Tensor& x) {
  return x.is_contiguous(at::MemoryFormat::ChannelsLast) && !x.is_contiguous();
}

}  // namespace

std::pair<torch::Tensor, torch::Tensor> max_mean_over_channels(const torch::Tensor& x) {
  TORCH_CHECK(x.dim() == 4, "x must be [B,C,H,W], got ", x.sizes());
  if (!fused_cpu_kernel_applies(x)) return {x.amax(1, true), x.mean(1, true)};
  const int64_t B = x.size(0), C = x.size(1), H = x.size(2), W = x.size(3);
  const auto r =
      pooled_channels_last(x) ? MaxMeanPool::apply(x.permute({0, 2, 3, 1}), C, 1) : MaxMeanPool::apply(x, C, H * W);
  return {r[0].view({B, 1, H, W}), r[1].view({B, 1, H, W})};
}

std::pair<torch::Tensor, torch::Tensor> max_mean_over_space(const torch::Tensor& x) {
  TORCH_CHECK(x.dim() == 4, "x must be [B,C,H,W], got ", x.sizes());
  if (!fused_cpu_kernel_applies(x)) return {x.amax({2, 3}, true), x.mean({2, 3}, true)};
  const int64_t B = x.size(0), C = x.size(1), HW = x.size(2) * x.size(3);
  const auto r =
      pooled_channels_last(x) ? MaxMeanPool::apply(x.permute({0, 2, 3, 1}), HW, C) : MaxMeanPool::apply(x, HW, 1);
  return {r[0].view({B, C, 1, 1}), r[1].view({B, C, 1, 1})};
}

FeatureRefinementImpl::FeatureRefinementImpl(const FeatureRefinementOptions& o) : options(o) {
  TORCH_CHECK(o.channels >= 1 && o.ratio >= 1, "FR needs channels >= 1 and ratio >= 1, got ", o.channels, " and ",
              o.ratio);
  const int64_t hidden = std::max(o.min_hidden, o.channels / o.ratio);
  // The shared MLP as 1x1 convolutions without bias (as in common CBAM implementations).
  mlp_in = register_module("mlp_in", Conv2d(torch::nn::Conv2dOptions(o.channels, hidden, 1).bias(false)));
  mlp_out = register_module("mlp_out", Conv2d(torch::nn::Conv2dOptions(hidden, o.channels, 1).bias(false)));
  spatial =
      register_module("spatial", Conv2d(torch::nn::Conv2dOptions(2, 1, o.kernel).padding(o.kernel / 2).bias(false)));
  if (o.spatial_bn) spatial_bn = register_module("spatial_bn", SyncBatchNorm2d(1));
}

torch::Tensor FeatureRefinementImpl::channel_gate(const torch::Tensor& x) {
  TORCH_CHECK(x.dim() == 4 && x.size(1) == options.channels, "FR input must be [B,", options.channels, ",H,W], got ",
              x.sizes());
  const auto [mx, avg] = max_mean_over_space(x);
  return channel_gate_of(mx, avg);
}

torch::Tensor FeatureRefinementImpl::channel_gate_of(const torch::Tensor& max, const torch::Tensor& mean) {
  auto mlp = [this](const torch::Tensor& t) { return conv2d(*mlp_out, torch::relu(conv2d(*mlp_in, t))); };
  return torch::sigmoid(mlp(mean) + mlp(max));
}

torch::Tensor FeatureRefinementImpl::spatial_gate(const torch::Tensor& f1) {
  const auto [mx, avg] = max_mean_over_channels(f1);
  return spatial_gate_of(mx, avg);
}

torch::Tensor FeatureRefinementImpl::spatial_gate_of(const torch::Tensor& max, const torch::Tensor& mean) {
  return spatial_gate_from(conv2d(*spatial, torch::cat({max, mean}, 1)));
}

torch::Tensor FeatureRefinementImpl::spatial_gate_from(const torch::Tensor& conv_out) {
  return torch::sigmoid(options.spatial_bn ? spatial_bn(conv_out) : conv_out);
}

torch::Tensor FeatureRefinementImpl::forward(const torch::Tensor& x) {
  const auto f1 = x * channel_gate(x);
  return f1 * spatial_gate(f1);
}

}  // namespace geo
