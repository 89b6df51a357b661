// oneDNN's prepacked float convolution: LibTorch's mkldnn_prepacked::conv2d_prepack / conv2d_run,
// what its frozen TorchScript graphs run on CPU. The kernel is reordered once, for activations in
// channels-last order, which the convolution then reads and writes where they lie, with the ReLU
// fused into it. Against at::mkldnn_convolution on oneDNN-blocked tensors that saves two reorders of
// the activations per call and the ReLU's pass over the output (ResNet-50's bottlenecks at 128x416:
// 10-15% of their time on a 2-core EPYC with AVX-512).
#pragma once

#include <torch/torch.h>

namespace geo {

class PrepackedConv {
 public:
  PrepackedConv() = default;  // none: operator bool is false
  // weight [Co,Ci,kh,kw] and bias [Co], float32 on the CPU; `input` the sizes [B,Ci,H,W] oneDNN lays
  // the kernel out for (inputs of other sizes run too, oneDNN then reorders the kernel per call).
  // None where this LibTorch lacks the ops or oneDNN cannot run the convolution.
  static PrepackedConv make(const torch::Tensor& weight, const torch::Tensor& bias, torch::IntArrayRef stride,
                            torch::IntArrayRef padding, torch::IntArrayRef input, bool relu);
  explicit operator bool() const { return !context_.isNone(); }
  // x [B,Ci,H,W] (made channels-last first when it is not) -> [B,Co,H',W'], channels-last.
  torch::Tensor operator()(const torch::Tensor& x) const;

 private:
  c10::IValue context_;
};

}  // namespace geo
