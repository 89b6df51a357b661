// BatchNorm over the batches of every process of a data-parallel group (PyTorch's SyncBatchNorm).
#pragma once

#include <torch/torch.h>

#include <functional>
#include <memory>
#include <ostream>

namespace geo {

// Sums a tensor in place over every process of a data-parallel group (an all-reduce), for
// synchronised BatchNorm; train/distributed.h makes one from a process group.
using SumAcrossProcesses = std::function<void(torch::Tensor&)>;

// BatchNorm2d of geo's networks: PyTorch's BatchNorm2d (the same computation, parameters and
// buffers under the same names: weight, bias, running_mean, running_var, num_batches_tracked) that,
// in training mode with `sync` set, normalises over the batches of every process instead
// (sync_batch_norm; PyTorch's SyncBatchNorm). Every BatchNorm of the networks is one, so a
// data-parallel run synchronises them all (set_batchnorm_sync). Affine, with running statistics.
// (Not a subclass of torch::nn::BatchNorm2dImpl: LibTorch does not export the members such a
// subclass's vtable needs.)
class SyncBatchNorm2dImpl : public torch::nn::Cloneable<SyncBatchNorm2dImpl> {
 public:
  explicit SyncBatchNorm2dImpl(int64_t channels) : SyncBatchNorm2dImpl(torch::nn::BatchNormOptions(channels)) {}
  explicit SyncBatchNorm2dImpl(const torch::nn::BatchNormOptions& options);
  void reset() override;
  torch::Tensor forward(const torch::Tensor& x);
  void pretty_print(std::ostream& stream) const override;

  torch::nn::BatchNormOptions options;  // num_features, eps, momentum (a value; no cumulative average)
  torch::Tensor weight, bias, running_mean, running_var, num_batches_tracked;
  std::shared_ptr<const SumAcrossProcesses> sync;  // set: training mode sums over the processes
};
TORCH_MODULE(SyncBatchNorm2d);

// Every SyncBatchNorm2d inside `module` normalises with statistics over all processes (`sum`) in
// training mode, or with its own batch's again (nullptr); returns how many.
int set_batchnorm_sync(torch::nn::Module& module, std::shared_ptr<const SumAcrossProcesses> sum);

// BatchNorm (training mode) over the batches of all processes together (PyTorch's SyncBatchNorm):
// forward all-reduces per channel the sum, the sum of squares and the count, normalises with the
// global mean and (biased) variance and updates bn's running statistics with them (the unbiased
// variance, as BatchNorm2d); backward all-reduces the sums of dy and dy*x_hat, so each process gets
// the gradient of the sum of every process's loss with respect to its own inputs, as one process
// over the concatenated batch would. The gradients of gamma and beta are this process's own (the
// gradient averaging adds them up). Every process must call it in the same order.
// `sum` is kept alive by the autograd graph until backward has run.
torch::Tensor sync_batch_norm(const torch::Tensor& x, SyncBatchNorm2dImpl& bn,
                              std::shared_ptr<const SumAcrossProcesses> sum);

}  // namespace geo
