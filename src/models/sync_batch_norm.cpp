#include "models/sync_batch_norm.h"

#include <torch/autograd.h>

namespace geo {

namespace {

// The reduction, held by the autograd graph (an opaque capsule in the node's saved data).
struct SumHolder : torch::CustomClassHolder {
  explicit SumHolder(std::shared_ptr<const SumAcrossProcesses> f) : fn(std::move(f)) {}
  std::shared_ptr<const SumAcrossProcesses> fn;
};

// y = x_hat * gamma + beta with x_hat = (x - mean) * invstd; mean and invstd are the statistics over
// all processes (computed before, without autograd); backward accounts for their dependence on x.
struct SyncBatchNormFn : torch::autograd::Function<SyncBatchNormFn> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x,
                               const torch::Tensor& weight, const torch::Tensor& bias, const torch::Tensor& mean,
                               const torch::Tensor& invstd, double count,
                               const std::shared_ptr<const SumAcrossProcesses>& sum) {
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
    return {dx.to(x.scalar_type()),
            sum_dy_xhat.to(saved[1].scalar_type()),
            sum_dy.to(saved[1].scalar_type()),
            torch::Tensor(),
            torch::Tensor(),
            torch::Tensor(),
            torch::Tensor()};
  }
};

}  // namespace

torch::Tensor sync_batch_norm(const torch::Tensor& x, SyncBatchNorm2dImpl& bn,
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
    auto stats =
        torch::cat({xf.sum({0, 2, 3}, false, torch::kFloat64), (xf * xf).sum({0, 2, 3}, false, torch::kFloat64),
                    torch::full({1}, static_cast<double>(x.numel() / C), xf.options().dtype(torch::kFloat64))});
    (*sum)(stats);
    count = stats[2 * C].item<double>();
    TORCH_CHECK(count > 1, "sync_batch_norm: one value per channel over all processes; BatchNorm needs more");
    const auto mean64 = stats.narrow(0, 0, C) / count;
    const auto var64 = (stats.narrow(0, C, C) / count - mean64 * mean64).clamp_min(0);
    mean = mean64.to(torch::kFloat32);
    const auto var = var64.to(torch::kFloat32);
    invstd = torch::rsqrt(var64 + bn.options.eps()).to(torch::kFloat32);
    TORCH_CHECK(bn.options.momentum(), "sync_batch_norm: momentum must be a value");
    const double m = *bn.options.momentum();
    bn.running_mean.mul_(1 - m).add_(mean.to(bn.running_mean.scalar_type()), m);
    bn.running_var.mul_(1 - m).add_((var * (count / (count - 1))).to(bn.running_var.scalar_type()), m);
    bn.num_batches_tracked.add_(1);
  }
  return SyncBatchNormFn::apply(x, bn.weight, bn.bias, mean, invstd, count, sum);
}

SyncBatchNorm2dImpl::SyncBatchNorm2dImpl(const torch::nn::BatchNormOptions& o) : options(o) { reset(); }

void SyncBatchNorm2dImpl::reset() {
  TORCH_CHECK(options.affine() && options.track_running_stats(),
              "SyncBatchNorm2d: only affine BatchNorm with running statistics");
  const int64_t C = options.num_features();
  weight = register_parameter("weight", torch::ones({C}));
  bias = register_parameter("bias", torch::zeros({C}));
  running_mean = register_buffer("running_mean", torch::zeros({C}));
  running_var = register_buffer("running_var", torch::ones({C}));
  num_batches_tracked = register_buffer("num_batches_tracked", torch::tensor(0, torch::kLong));
}

torch::Tensor SyncBatchNorm2dImpl::forward(const torch::Tensor& x) {
  TORCH_CHECK(x.dim() == 4, "BatchNorm2d: expected a [B,C,H,W] input, got ", x.sizes());
  if (sync && is_training()) return sync_batch_norm(x, *this, sync);
  TORCH_CHECK(options.momentum(), "SyncBatchNorm2d: momentum must be a value");
  if (is_training()) num_batches_tracked += 1;  // as torch::nn::BatchNorm2d
  return torch::batch_norm(x, weight, bias, running_mean, running_var, is_training(), *options.momentum(),
                           options.eps(), at::globalContext().userEnabledCuDNN());
}

void SyncBatchNorm2dImpl::pretty_print(std::ostream& stream) const {
  stream << "geo::SyncBatchNorm2d(" << options.num_features() << ", eps=" << options.eps()
         << ", momentum=" << options.momentum().value_or(0) << (sync ? ", synchronised" : "") << ")";
}

int set_batchnorm_sync(torch::nn::Module& module, std::shared_ptr<const SumAcrossProcesses> sum) {
  int n = 0;
  for (auto& m : module.modules(/*include_self=*/true)) {
    if (auto* bn = m->as<SyncBatchNorm2dImpl>()) {
      bn->sync = sum;
      ++n;
    }
  }
  return n;
}

}  // namespace geo
