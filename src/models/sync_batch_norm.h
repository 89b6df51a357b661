// BatchNorm over the batches of every process of a data-parallel group (PyTorch's SyncBatchNorm).
#pragma once

#include <torch/torch.h>

#include <functional>
#include <memory>

namespace geo {

// Sums a tensor in place over every process of a data-parallel group (an all-reduce), for
// synchronised BatchNorm; train/distributed.h makes one from a process group.
using SumAcrossProcesses = std::function<void(torch::Tensor&)>;

// BatchNorm (training mode) over the batches of all processes together (PyTorch's SyncBatchNorm):
// forward all-reduces per channel the sum, the sum of squares and the count, normalises with the
// global mean and (biased) variance and updates bn's running statistics with them (the unbiased
// variance, as BatchNorm2d); backward all-reduces the sums of dy and dy*x_hat, so each process gets
// the gradient of the sum of every process's loss with respect to its own inputs, as one process
// over the concatenated batch would. The gradients of gamma and beta are this process's own (the
// gradient averaging adds them up). Every process must call it in the same order.
// `sum` is kept alive by the autograd graph until backward has run.
torch::Tensor sync_batch_norm(const torch::Tensor& x, torch::nn::BatchNorm2dImpl& bn,
                              std::shared_ptr<const SumAcrossProcesses> sum);

}  // namespace geo
