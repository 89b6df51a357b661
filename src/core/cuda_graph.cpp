#include "core/cuda_graph.h"

#include <spdlog/spdlog.h>

#include <stdexcept>

#ifdef GEO_WITH_CUDA
#include <ATen/autocast_mode.h>
#include <ATen/cuda/CUDAEvent.h>
#include <ATen/cuda/CUDAGraph.h>
#include <c10/cuda/CUDACachingAllocator.h>
#include <c10/cuda/CUDAGuard.h>
#include <c10/cuda/CUDAStream.h>
#endif

namespace geo {

#ifdef GEO_WITH_CUDA

namespace {

bool same_layout(const std::vector<torch::Tensor>& a, const std::vector<torch::Tensor>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (a[i].sizes() != b[i].sizes() || a[i].scalar_type() != b[i].scalar_type() || a[i].device() != b[i].device())
      return false;
  return true;
}

}  // namespace

struct CudaGraphCall::Impl {
  Fn fn;
  torch::Device device;
  int warmup;
  int calls = 0;
  bool captured = false;
  bool told_other_shapes = false;
  bool replayed = false;
  at::cuda::CUDAStream stream;
  std::vector<torch::Tensor> inputs, outputs;
  at::cuda::CUDAGraph graph;

  Impl(Fn f, const torch::Device& d, int w)
      : fn(std::move(f)), device(d), warmup(w), stream(at::cuda::getStreamFromPool(false, d.index())) {}

  // Captures fn on `stream` (current): the autocast cache off meanwhile, since a weight cast
  // cached during the capture would be a graph's tensor outside it.
  void capture() {
    // The warm-up's freed blocks back to the device first: the graph keeps a pool of its own for
    // everything the capture allocates, and both at once would double a step's peak memory.
    c10::cuda::CUDACachingAllocator::emptyCache();
    const bool cache = at::autocast::is_autocast_cache_enabled();
    at::autocast::set_autocast_cache_enabled(false);
    // Thread-local: the CUDA calls of other threads (the data loader pinning batches) go on
    // meanwhile; LibTorch's autograd thread still records the backward into this stream.
    graph.capture_begin({0, 0}, cudaStreamCaptureModeThreadLocal);
    try {
      outputs = fn(inputs);
    } catch (...) {
      at::autocast::set_autocast_cache_enabled(cache);
      try {
        graph.capture_end();
      } catch (...) {
      }
      throw;
    }
    graph.capture_end();
    at::autocast::set_autocast_cache_enabled(cache);
    captured = true;
  }
};

bool CudaGraphCall::available() { return true; }

CudaGraphCall::CudaGraphCall(Fn fn, const torch::Device& device, int warmup) {
  if (!device.is_cuda()) throw std::invalid_argument("CUDA graphs run on a CUDA device, not " + device.str());
  impl_ = std::make_unique<Impl>(std::move(fn), device, std::max(warmup, 1));
}

std::vector<torch::Tensor> CudaGraphCall::operator()(const std::vector<torch::Tensor>& inputs) {
  Impl& m = *impl_;
  const bool same = same_layout(inputs, m.inputs);
  if (!same && !m.captured) {  // (re)start: new static buffers, warm-up again
    m.inputs.clear();
    for (const auto& t : inputs) m.inputs.push_back(torch::empty(t.sizes(), t.options()));
    m.calls = 0;
  }
  const auto caller = at::cuda::getCurrentCUDAStream(m.device.index());
  if (!same && m.captured && !m.told_other_shapes) {
    spdlog::info("CUDA graph: inputs of other shapes than the captured ones run without the graph");
    m.told_other_shapes = true;
  }
  const bool graphed = same || !m.captured;
  if (graphed)
    for (size_t i = 0; i < inputs.size(); ++i) m.inputs[i].copy_(inputs[i], true);
  at::cuda::CUDAEvent ready;
  ready.record(caller);
  ready.block(m.stream);
  std::vector<torch::Tensor> out;
  m.replayed = graphed && (m.captured || m.calls >= m.warmup);
  {
    c10::cuda::CUDAStreamGuard guard(m.stream);
    if (!graphed) {
      out = m.fn(inputs);
    } else if (m.captured) {
      m.graph.replay();
      out = m.outputs;
    } else if (m.calls < m.warmup) {
      out = m.fn(m.inputs);
      ++m.calls;
    } else {
      m.capture();
      m.graph.replay();  // the capture recorded the work; this does it
      out = m.outputs;
    }
    at::cuda::CUDAEvent done;
    done.record(m.stream);
    done.block(caller);
  }
  return out;
}

bool CudaGraphCall::replayed() const { return impl_->replayed; }
bool CudaGraphCall::next_call_captures() const { return !impl_->captured && impl_->calls >= impl_->warmup; }

#else

struct CudaGraphCall::Impl {};

bool CudaGraphCall::available() { return false; }

CudaGraphCall::CudaGraphCall(Fn, const torch::Device& device, int) {
  throw std::invalid_argument("CUDA graphs on " + device.str() + ": this geo was built without CUDA");
}

std::vector<torch::Tensor> CudaGraphCall::operator()(const std::vector<torch::Tensor>&) {
  throw std::logic_error("CUDA graphs: this geo was built without CUDA");
}

bool CudaGraphCall::replayed() const { return false; }
bool CudaGraphCall::next_call_captures() const { return false; }

#endif

CudaGraphCall::~CudaGraphCall() = default;

}  // namespace geo
