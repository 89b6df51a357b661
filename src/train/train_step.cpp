#include "train/train_step.h"

#include <cmath>
#include <map>
#include <sstream>
#include <type_traits>

namespace geo {

LrSchedule LrSchedule::of(const StageConfig& s) {
  LrSchedule l;
  l.base = s.learning_rate;
  if (s.lr_schedule == LrScheduleKind::kStep) {
    l.step = s.lr_step;
    l.gamma = s.lr_gamma;
  }
  return l;
}

double LrSchedule::at(int64_t iteration) const {
  if (step <= 0) return base;
  return base * std::pow(gamma, static_cast<double>(iteration / step));
}

namespace {

// The key of a parameter's state in torch::optim::Optimizer::state(): the TensorImpl address, as
// a string in LibTorch 1.x (c10::guts::to_string) and as the pointer itself in 2.x.
template <class Key>
Key state_key(const torch::Tensor& p) {
  if constexpr (std::is_same_v<Key, std::string>) {
    std::ostringstream s;
    s << p.unsafeGetTensorImpl();
    return s.str();
  } else {
    return p.unsafeGetTensorImpl();
  }
}

}  // namespace

const torch::optim::AdamParamState* adam_state_of(const torch::optim::Adam& adam, const torch::Tensor& p) {
  using Key = typename std::decay_t<decltype(adam.state())>::key_type;
  const auto it = adam.state().find(state_key<Key>(p));
  if (it == adam.state().end()) return nullptr;
  return &static_cast<const torch::optim::AdamParamState&>(*it->second);
}

torch::Tensor MultiTensorAdam::step(LossClosure closure) {
  for (const auto& group : param_groups())
    if (static_cast<const torch::optim::AdamOptions&>(group.options()).amsgrad()) return Adam::step(closure);
  torch::NoGradGuard no_grad;
  torch::Tensor loss;
  if (closure) {
    at::AutoGradMode enable_grad(true);
    loss = closure();
  }
  using Key = typename std::decay_t<decltype(state())>::key_type;
  for (auto& group : param_groups()) {
    const auto& o = static_cast<const torch::optim::AdamOptions&>(group.options());
    // Parameters that first got a gradient later have taken fewer steps: one update per step count.
    struct Lists {
      std::vector<torch::Tensor> params, grads, exp_avgs, exp_avg_sqs;
    };
    std::map<int64_t, Lists> by_step;
    for (auto& p : group.params()) {
      if (!p.grad().defined()) continue;
      TORCH_CHECK(!p.grad().is_sparse(), "Adam does not support sparse gradients");
      const Key key = state_key<Key>(p);
      auto it = state().find(key);
      if (it == state().end()) {
        auto fresh = std::make_unique<torch::optim::AdamParamState>();
        fresh->step(0);
        fresh->exp_avg(torch::zeros_like(p, torch::MemoryFormat::Preserve));
        fresh->exp_avg_sq(torch::zeros_like(p, torch::MemoryFormat::Preserve));
        it = state().emplace(key, std::move(fresh)).first;
      }
      auto& st = static_cast<torch::optim::AdamParamState&>(*it->second);
      st.step(st.step() + 1);
      Lists& l = by_step[st.step()];
      l.params.push_back(p);
      l.grads.push_back(p.grad());
      l.exp_avgs.push_back(st.exp_avg());
      l.exp_avg_sqs.push_back(st.exp_avg_sq());
    }
    const double beta1 = std::get<0>(o.betas()), beta2 = std::get<1>(o.betas());
    for (auto& [step, l] : by_step) {
      const double bias_correction1 = 1 - std::pow(beta1, static_cast<double>(step));
      const double bias_correction2 = 1 - std::pow(beta2, static_cast<double>(step));
      if (o.weight_decay() != 0) l.grads = at::_foreach_add(l.grads, l.params, o.weight_decay());
      at::_foreach_mul_(l.exp_avgs, beta1);
      at::_foreach_add_(l.exp_avgs, l.grads, 1 - beta1);
      at::_foreach_mul_(l.exp_avg_sqs, beta2);
      at::_foreach_addcmul_(l.exp_avg_sqs, l.grads, l.grads, 1 - beta2);
      auto denom = at::_foreach_sqrt(l.exp_avg_sqs);
      at::_foreach_div_(denom, std::sqrt(bias_correction2));
      at::_foreach_add_(denom, o.eps());
      at::_foreach_addcdiv_(l.params, l.exp_avgs, denom, -o.lr() / bias_correction1);
    }
  }
  return loss;
}

namespace {

std::vector<torch::Tensor> defined_gradients(const std::vector<torch::Tensor>& parameters) {
  std::vector<torch::Tensor> grads;
  for (const auto& p : parameters)
    if (p.grad().defined()) grads.push_back(p.grad());
  return grads;
}

}  // namespace

torch::Tensor gradient_norm(const std::vector<torch::Tensor>& parameters) {
  const auto grads = defined_gradients(parameters);
  if (grads.empty()) return {};
  return torch::stack(at::_foreach_norm(grads)).norm();
}

std::unique_ptr<torch::optim::Adam> make_adam(const std::vector<torch::Tensor>& parameters, double lr,
                                              const OptimizerConfig& o) {
  return std::make_unique<MultiTensorAdam>(
      parameters, torch::optim::AdamOptions(lr).betas({o.beta1, o.beta2}).eps(o.eps).weight_decay(o.weight_decay));
}

TrainStep::TrainStep(Networks& nets, const Config& config, const StageConfig& stage)
    : nets_(nets), config_(config), stage_(stage) {
  nets_.set_modes(stage_);
  nets_.set_trainable(stage_);
  params_ = nets_.trainable_parameters();
  adam_ = make_adam(params_, stage_.learning_rate, config_.optimizer);
}

void TrainStep::set_gradient_averager(GradientAverager* averager, bool overlap) {
  averager_ = averager;
  overlap_ = averager && overlap;
  if (overlap_) averager_->attach(params_);
}

StepResult TrainStep::run(const torch::Tensor& tgt, const torch::Tensor& srcs, const torch::Tensor& K, double lr) {
  for (auto& group : adam_->param_groups()) static_cast<torch::optim::AdamOptions&>(group.options()).lr(lr);
  adam_->zero_grad();
  StepResult r;
  r.out = compute_losses(nets_, tgt, srcs, K, stage_, config_, teacher_);
  // Two device-to-host copies per step: the loss terms (to skip backward on a non-finite loss:
  // grid_sample's CPU backward crashes on NaN coordinates), then the gradient norm.
  r.losses = r.out.losses.values();
  if (r.out.K.defined()) {
    const auto k = r.out.K.detach().mean(0).to(torch::kCPU, torch::kFloat64);
    r.camera = {k[0][0].item<double>(), k[1][1].item<double>(), k[0][2].item<double>(), k[1][2].item<double>()};
  }
  const bool loss_finite = std::isfinite(r.losses.back().second);  // the total
  if (overlap_) averager_->begin_step();
  if (loss_finite) r.out.losses.total.backward();
  // Distributed: every process takes part, finite or not; a non-finite one sends NaN, so the
  // averaged gradients are non-finite everywhere and every process skips the step.
  if (overlap_) averager_->finish(!loss_finite);
  else if (averager_) averager_->average(params_, !loss_finite);
  torch::Tensor norm;
  if (loss_finite || averager_) {
    norm = gradient_norm(params_);
    r.grad_norm = norm.defined() ? norm.item<double>() : 0.0;
  }
  r.finite = loss_finite && std::isfinite(r.grad_norm);
  if (!r.finite) {
    adam_->zero_grad();
    return r;
  }
  const double clip = config_.optimizer.grad_clip;
  if (clip > 0 && norm.defined()) {
    // torch::nn::utils::clip_grad_norm_'s rule, on the norm already computed.
    const double coef = clip / (r.grad_norm + 1e-6);
    if (coef < 1) {
      auto grads = defined_gradients(params_);
      at::_foreach_mul_(grads, coef);
    }
  }
  adam_->step();
  return r;
}

}  // namespace geo
