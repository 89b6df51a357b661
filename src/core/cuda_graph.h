// A function of tensors run as one CUDA graph: the first calls run it eagerly (they warm up cuDNN's
// algorithm choice, cuBLAS's workspace and the caching allocator), the next one captures it
// (at::cuda::CUDAGraph) and every later call replays the capture: one launch for the thousands of
// small kernels that otherwise go one by one through the dispatcher. Used by the training step
// (train/train_step.h, run.cuda_graphs) and by graphed inference (geo_bench's pipeline rows).
//
// What the function may do: read only its arguments (static buffers, refilled by each call) and
// tensors that keep their storage (parameters, optimiser state), and make no host reads (.item(),
// .cpu(), data-dependent shapes), no host-to-device copies and no random draws. What a caller gets
// back is the capture's own output tensors: valid until the next call overwrites them.
// A build without CUDA compiles this too: available() is false there and a call throws.
#pragma once

#include <torch/types.h>

#include <functional>
#include <memory>
#include <vector>

namespace geo {

class CudaGraphCall {
 public:
  using Fn = std::function<std::vector<torch::Tensor>(const std::vector<torch::Tensor>&)>;
  // True where this build has CUDA graphs (a CUDA LibTorch).
  static bool available();

  // `warmup`: eager calls before the capture (at least 1). Inputs must lie on `device` (CUDA).
  CudaGraphCall(Fn fn, const torch::Device& device, int warmup = 2);
  ~CudaGraphCall();
  CudaGraphCall(const CudaGraphCall&) = delete;
  CudaGraphCall& operator=(const CudaGraphCall&) = delete;

  // Copies `inputs` into the static buffers (on the caller's stream), runs, captures or replays
  // `fn` on a stream of its own, and makes the caller's stream wait for it. Inputs of other
  // shapes than the captured ones run eagerly (said once in the log).
  std::vector<torch::Tensor> operator()(const std::vector<torch::Tensor>& inputs);

  bool replayed() const;            // the last call ran the graph (its outputs are the capture's)
  bool next_call_captures() const;  // the coming call with the same shapes is the capture

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace geo
