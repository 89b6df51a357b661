#include "train/train_step.h"

#include <cmath>

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

std::unique_ptr<torch::optim::Adam> make_adam(const std::vector<torch::Tensor>& parameters, double lr,
                                              const OptimizerConfig& o) {
  return std::make_unique<torch::optim::Adam>(
      parameters,
      torch::optim::AdamOptions(lr).betas({o.beta1, o.beta2}).eps(o.eps).weight_decay(o.weight_decay));
}

TrainStep::TrainStep(Networks& nets, const Config& config, const StageConfig& stage)
    : nets_(nets), config_(config), stage_(stage) {
  nets_.set_modes(stage_);
  nets_.set_trainable(stage_);
  params_ = nets_.trainable_parameters();
  adam_ = make_adam(params_, stage_.learning_rate, config_.optimizer);
}

StepResult TrainStep::run(const torch::Tensor& tgt, const torch::Tensor& srcs, const torch::Tensor& K,
                          double lr) {
  for (auto& group : adam_->param_groups())
    static_cast<torch::optim::AdamOptions&>(group.options()).lr(lr);
  adam_->zero_grad();
  StepResult r;
  r.out = compute_losses(nets_, tgt, srcs, K, stage_, config_);
  const bool loss_finite = std::isfinite(r.out.losses.total.item<double>());
  if (loss_finite) r.out.losses.total.backward();
  // Distributed: every process takes part, finite or not; a non-finite one sends NaN, so the
  // averaged gradients are non-finite everywhere and every process skips the step.
  if (averager_) averager_->average(params_, !loss_finite);
  if (loss_finite || averager_) {
    std::vector<torch::Tensor> norms;
    for (const auto& p : params_)
      if (p.grad().defined()) norms.push_back(p.grad().norm());
    r.grad_norm = norms.empty() ? 0.0 : torch::stack(norms).norm().item<double>();
  }
  r.finite = loss_finite && std::isfinite(r.grad_norm);
  if (!r.finite) {
    adam_->zero_grad();
    return r;
  }
  if (config_.optimizer.grad_clip > 0) torch::nn::utils::clip_grad_norm_(params_, config_.optimizer.grad_clip);
  adam_->step();
  return r;
}

}  // namespace geo
