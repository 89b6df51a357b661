// GradientAverager (train/distributed.h): gradients summed across processes in buckets, each
// started as soon as its last gradient is ready, overlapping the rest of the backward pass.
#include "train/distributed.h"

#include <stdexcept>
#include <string>
#include <vector>

namespace geo {

void GradientAverager::build(const std::vector<torch::Tensor>& parameters) {
  bool same = parameters.size() == params_.size();
  for (size_t i = 0; same && i < parameters.size(); ++i) same = parameters[i].is_same(params_[i]);
  if (same && !buckets_.empty()) return;
  detach();
  params_ = parameters;
  buckets_.clear();
  bucket_of_.assign(params_.size(), 0);
  slot_of_.assign(params_.size(), 0);
  bytes_ = 0;
  int64_t size = 0;
  for (size_t k = params_.size(); k-- > 0;) {  // reverse: the order backward produces gradients in
    const auto& p = params_[k];
    const int64_t n = p.numel(), item = static_cast<int64_t>(p.element_size());
    if (buckets_.empty() || (size > 0 && (size + n) * item > bucket_bytes_)) {
      buckets_.emplace_back();
      size = 0;
    }
    Bucket& b = buckets_.back();
    bucket_of_[k] = buckets_.size() - 1;
    slot_of_[k] = b.members.size();
    b.members.push_back(k);
    b.offsets.push_back(size);
    size += n;
  }
  for (auto& b : buckets_) {
    int64_t n = 0;
    for (size_t m : b.members) n += params_[m].numel();
    b.flat = torch::zeros({n}, params_[b.members[0]].options().requires_grad(false));
    bytes_ += n * static_cast<int64_t>(b.flat.element_size());
  }
}

void GradientAverager::attach(const std::vector<torch::Tensor>& parameters) {
  build(parameters);
  if (!hooks_.empty()) return;
  for (size_t i = 0; i < params_.size(); ++i)
    hooks_.push_back(params_[i].register_hook([this, i](torch::Tensor grad) { mark_ready(i, grad); }));
}

void GradientAverager::detach() {
  for (size_t i = 0; i < hooks_.size(); ++i) params_[i].remove_hook(hooks_[i]);
  hooks_.clear();
}

void GradientAverager::begin_step() {
  ready_.assign(params_.size(), 0);
  for (auto& b : buckets_) {
    b.ready = 0;
    b.started = false;
    b.wait = nullptr;
  }
  next_ = 0;
  started_early_ = 0;
}

void GradientAverager::start(Bucket& b, bool poison) {
  if (poison) b.flat.fill_(std::numeric_limits<float>::quiet_NaN());
  b.wait = group_.start_all_reduce_sum(b.flat);
  b.started = true;
}

void GradientAverager::mark_ready(size_t index, const torch::Tensor& grad) {
  if (ready_.size() != params_.size() || ready_[index]) return;  // outside a step, or a second backward
  Bucket& b = buckets_[bucket_of_[index]];
  b.flat.narrow(0, b.offsets[slot_of_[index]], params_[index].numel()).copy_(grad.detach().reshape(-1));
  ready_[index] = 1;
  ++b.ready;
  // In bucket order only: every process starts the same collectives in the same order.
  while (next_ < buckets_.size() && buckets_[next_].ready == buckets_[next_].members.size()) {
    start(buckets_[next_++], false);
    ++started_early_;
  }
}

void GradientAverager::finish(bool poison) {
  // What backward did not produce: the gradient as it stands, else zeros.
  for (; next_ < buckets_.size(); ++next_) {
    Bucket& b = buckets_[next_];
    for (size_t j = 0; j < b.members.size(); ++j) {
      const size_t i = b.members[j];
      if (ready_[i]) continue;
      auto slot = b.flat.narrow(0, b.offsets[j], params_[i].numel());
      if (params_[i].grad().defined()) slot.copy_(params_[i].grad().detach().reshape(-1));
      else slot.zero_();
    }
    start(b, poison);
  }
  const double world = static_cast<double>(group_.size());
  for (auto& b : buckets_) {
    b.wait();
    b.flat.div_(world);
    for (size_t j = 0; j < b.members.size(); ++j) {
      auto& p = params_[b.members[j]];
      if (p.grad().defined()) p.mutable_grad().view(-1).copy_(b.flat.narrow(0, b.offsets[j], p.numel()));
    }
  }
  ready_.clear();
}

void GradientAverager::average(const std::vector<torch::Tensor>& parameters, bool poison) {
  build(parameters);
  begin_step();
  finish(poison);
}

}  // namespace geo
