#include "train/train_step.h"

#include <torch/version.h>

#include <cmath>
#include <map>
#include <sstream>
#include <type_traits>

// LibTorch's fused Adam with a tensor learning rate, device step counts and found_inf, on CPU and
// CUDA: 2.4 and later.
#if TORCH_VERSION_MAJOR > 2 || (TORCH_VERSION_MAJOR == 2 && TORCH_VERSION_MINOR >= 4)
#define GEO_FUSED_ADAM 1
#endif

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

// The Adam state of `p`, made (step 0, zero moments) when it has none yet: what torch::optim::Adam
// does at a parameter's first update.
torch::optim::AdamParamState& adam_state_for(torch::optim::Adam& adam, const torch::Tensor& p) {
  using Key = typename std::decay_t<decltype(adam.state())>::key_type;
  const Key key = state_key<Key>(p);
  auto it = adam.state().find(key);
  if (it == adam.state().end()) {
    auto fresh = std::make_unique<torch::optim::AdamParamState>();
    fresh->step(0);
    fresh->exp_avg(torch::zeros_like(p, torch::MemoryFormat::Preserve));
    fresh->exp_avg_sq(torch::zeros_like(p, torch::MemoryFormat::Preserve));
    it = adam.state().emplace(key, std::move(fresh)).first;
  }
  return static_cast<torch::optim::AdamParamState&>(*it->second);
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
      auto& st = adam_state_for(*this, p);
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

TrainStep::~TrainStep() = default;

void TrainStep::set_gradient_averager(GradientAverager* averager, bool overlap) {
  averager_ = averager;
  overlap_ = averager && overlap;
  if (overlap_) averager_->attach(params_);
}

bool TrainStep::device_checks_available() {
#ifdef GEO_FUSED_ADAM
  return true;
#else
  return false;
#endif
}

bool TrainStep::graphs_possible() const {
  return CudaGraphCall::available() && !params_.empty() && params_.front().is_cuda();
}

TrainStep::Mode TrainStep::mode() const {
  if (mode_) return *mode_;
  if (graphs_possible() && config_.run.cuda_graphs && !averager_ && device_checks_available()) return Mode::kGraphed;
  return Mode::kEager;
}

void TrainStep::set_mode(Mode mode) {
  if (device_updates_started_)
    throw std::logic_error("TrainStep::set_mode: the step has run with device checks already; its mode stays");
  if (mode != Mode::kEager) {
    if (!device_checks_available())
      throw std::runtime_error(std::string("the training step with device-side checks needs LibTorch 2.4 or later "
                                           "(its fused Adam); this is ") +
                               TORCH_VERSION + ": run.cuda_graphs does nothing here");
    if (averager_) throw std::runtime_error("multi-process training runs the eager step (run.cuda_graphs is ignored)");
  }
  if (mode == Mode::kGraphed && !graphs_possible())
    throw std::runtime_error("CUDA graphs need a CUDA build of geo and the networks on a CUDA device");
  mode_ = mode;
}

StepResult TrainStep::run(const torch::Tensor& tgt, const torch::Tensor& srcs, const torch::Tensor& K, double lr) {
  if (!mode_) mode_ = mode();
  return *mode_ == Mode::kEager ? run_eager(tgt, srcs, K, lr) : run_device_checks(tgt, srcs, K, lr);
}

StepResult TrainStep::run_eager(const torch::Tensor& tgt, const torch::Tensor& srcs, const torch::Tensor& K,
                                double lr) {
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

StepResult TrainStep::run_device_checks(const torch::Tensor& tgt, const torch::Tensor& srcs, const torch::Tensor& K,
                                        double lr) {
  // A fill on the device, not a copy from the host: a graph input like the batch.
  const std::vector<torch::Tensor> in{tgt, srcs, K, torch::full({}, lr, tgt.options().dtype(torch::kFloat32))};
  std::vector<torch::Tensor> out;
  bool replayed = false;
  if (*mode_ == Mode::kGraphed) {
    if (!graph_)
      graph_ = std::make_unique<CudaGraphCall>([this](const std::vector<torch::Tensor>& x) { return device_update(x); },
                                               tgt.device(), 2);
    capturing_ = graph_->next_call_captures();
    out = (*graph_)(in);
    capturing_ = false;
    replayed = graph_->replayed();
    if (replayed && !graph_out_.losses.total.defined()) graph_out_ = device_out_;  // the capture's maps
  } else {
    out = device_update(in);
  }
  device_updates_started_ = true;
  const auto host = out.at(0).cpu();  // the step's one read, after the update
  const auto h = host.accessor<double, 1>();
  const int64_t n = static_cast<int64_t>(loss_names_.size());
  StepResult r;
  for (int64_t i = 0; i < n; ++i) r.losses.emplace_back(loss_names_[static_cast<size_t>(i)], h[i]);
  r.finite = h[n + 1] == 0;
  r.grad_norm = r.finite ? h[n] : 0.0;
  if (host.size(0) == n + 6) r.camera = {h[n + 2], h[n + 3], h[n + 4], h[n + 5]};
  if (r.finite)  // the device counts advanced with the update; the checkpointed counts follow
    for (auto* st : device_states_) st->step(st->step() + 1);
  r.out = replayed ? graph_out_ : device_out_;
  return r;
}

std::vector<torch::Tensor> TrainStep::device_update(const std::vector<torch::Tensor>& in) {
#ifdef GEO_FUSED_ADAM
  const torch::Tensor &tgt = in.at(0), &srcs = in.at(1), &K = in.at(2), &lr = in.at(3);
  // Gradients are assigned, not accumulated: under capture they are the graph's own tensors.
  for (auto& p : params_) p.mutable_grad() = torch::Tensor();
  StepOutput out = compute_losses(nets_, tgt, srcs, K, stage_, config_, teacher_);
  out.losses.total.backward();
  TORCH_CHECK(adam_->param_groups().size() == 1, "the device-checked step takes one Adam parameter group");
  auto& group = adam_->param_groups().front();
  const auto& o = static_cast<const torch::optim::AdamOptions&>(group.options());
  TORCH_CHECK(!o.amsgrad(), "the device-checked step has no amsgrad");
  std::vector<torch::Tensor> ps, grads, exp_avgs, exp_avg_sqs, steps;
  device_states_.clear();
  for (auto& p : group.params()) {
    if (!p.grad().defined()) continue;
    auto step = device_steps_.find(p.unsafeGetTensorImpl());
    // Fresh state is made by the eager calls before a capture: made during one, its zeros would be
    // written again by every replay.
    if (step == device_steps_.end() || !adam_state_of(*adam_, p))
      TORCH_CHECK(!capturing_, "the CUDA graph's step met a parameter without Adam state: ", p.sizes());
    auto& st = adam_state_for(*adam_, p);
    if (step == device_steps_.end())
      step = device_steps_
                 .emplace(p.unsafeGetTensorImpl(),
                          torch::full({}, static_cast<double>(st.step()), p.options().dtype(torch::kFloat32)))
                 .first;
    device_states_.push_back(&st);
    ps.push_back(p);
    grads.push_back(p.grad());
    exp_avgs.push_back(st.exp_avg());
    exp_avg_sqs.push_back(st.exp_avg_sq());
    steps.push_back(step->second);
  }
  TORCH_CHECK(!ps.empty(), "the training step produced no gradient");
  const auto norm = gradient_norm(ps);
  const auto skip =
      torch::logical_not(torch::isfinite(out.losses.total.detach()) & torch::isfinite(norm)).to(torch::kFloat32);
  std::optional<torch::Tensor> divide_by;  // optimizer.grad_clip: clip_grad_norm_'s factor, inverted
  if (config_.optimizer.grad_clip > 0) divide_by = torch::clamp_min((norm + 1e-6) / config_.optimizer.grad_clip, 1.0);
  at::_foreach_add_(steps, 1);
  at::_fused_adam_(ps, grads, exp_avgs, exp_avg_sqs, {}, steps, lr, std::get<0>(o.betas()), std::get<1>(o.betas()),
                   o.weight_decay(), o.eps(), /*amsgrad=*/false, /*maximize=*/false, divide_by, skip);
  at::_foreach_sub_(steps, std::vector<torch::Tensor>(steps.size(), skip));  // a skipped update takes no step
  auto [names, values] = out.losses.stacked();
  loss_names_ = names;
  std::vector<torch::Tensor> summary{values, norm.to(torch::kFloat64).view({1}), skip.to(torch::kFloat64).view({1})};
  if (out.K.defined()) {
    const auto k = out.K.detach().mean(0).to(torch::kFloat64);
    summary.push_back(torch::stack({k[0][0], k[1][1], k[0][2], k[1][2]}));
  }
  device_out_ = std::move(out);
  return {torch::cat(summary)};
#else
  (void)in;
  throw std::logic_error("the device-checked training step needs LibTorch 2.4 or later");
#endif
}
}  // namespace geo
