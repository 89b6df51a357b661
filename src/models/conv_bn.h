// Convolution + BatchNorm + ReLU, the block every network here is built of, with BatchNorm folded
// (and the kernels prepacked for oneDNN) for inference and synchronised across processes in training.
#pragma once

#include "models/conv.h"
#include "models/prepacked_conv.h"
#include "models/sync_batch_norm.h"

#include <torch/torch.h>

#include <functional>
#include <memory>
#include <mutex>

namespace geo {

// conv (k x k, stride, symmetric padding k/2) -> BatchNorm -> ReLU (relu optional). The conv has
// no bias because BatchNorm follows (GeoNet's slim.conv2d with batch_norm).
struct ConvBnImpl : torch::nn::Module {
  // `upsampled`: the module is run through forward_upsampled (a decoder's upconv), so folding also
  // prepacks the phase kernels that needs (16/9 of the kernel's size: only where they are used).
  ConvBnImpl(int64_t in, int64_t out, int64_t kernel, int64_t stride = 1, bool relu = true, bool upsampled = false);
  torch::Tensor forward(const torch::Tensor& x);
  // forward(nearest_upsample_x2(x)) for a 3x3 stride-1 ConvBn (GeoNet's upconv), computed at x's
  // resolution: see conv3x3_of_upsampled. Same values up to rounding, 2.25x fewer multiply-adds.
  // Below kMinSubpixelArea input pixels (the 2x7 bottleneck of a 128x416 image) the four phase
  // kernels (16/9 of the weights) cost more memory traffic than they save: plain upsample + conv.
  torch::Tensor forward_upsampled(const torch::Tensor& x);
  static constexpr int64_t kMinSubpixelArea = 32;
  // Inference only: folds BatchNorm's running statistics and affine into one convolution with a
  // bias (w' = w·γ/√(σ²+ε), b' = β − μ·γ/√(σ²+ε)), so forward is a single conv (+ ReLU). The folded
  // tensors are not registered: fold after loading weights and moving to the device; a folded
  // module refuses to run in training mode. `dtype`: the folded tensors' type (computed in float32).
  // On CPU, where LibTorch has oneDNN (MKL-DNN), the folded kernels (and forward_upsampled's phase
  // kernels) are also reordered once into oneDNN's layout (at::conv2d reorders the weights on every
  // call): in float32 as oneDNN's prepacked convolution with the ReLU fused, which reads and writes
  // channels-last activations as they lie (models/prepacked_conv.h; a network's layers then pass
  // channels-last tensors on, and its outputs are made dense again); in bf16, and forward_upsampled's
  // phase kernels, as blocked kernels (PyTorch's torch.utils.mkldnn) with the activations reordered
  // per call. Same results up to rounding. The reorder happens at the first float call (once,
  // whichever thread makes it), not here: a model that runs in int8 never pays it (40% of opening
  // the paper's model). A prepacked module keeps only the packed kernel
  // (the plain folded one is computed again where a call needs it): a loaded model holds its
  // weights about twice (the parameters and the packed kernels), not four times; in float32 no
  // folded kernel is held before the packing either (an int8 model never makes a float one).
  void fold_batchnorm(torch::Dtype dtype = torch::kFloat32);
  bool folded() const { return folded_bias_.defined(); }
  bool prepacked() const {
    return packed_weight_.defined() || static_cast<bool>(packed_conv_);
  }  // (after the first float call)
  // The folded kernel and bias (undefined before fold_batchnorm): what the int8 path quantizes.
  torch::Tensor folded_weight() const;
  // BatchNorm's per-channel factor γ/√(σ²+ε): the folded kernel is the conv's weight times it.
  torch::Tensor bn_scale() const;
  const torch::Tensor& folded_bias() const { return folded_bias_; }
  // Inference in int8 only: lets go of the float kernel (the conv's weight and any folded or packed
  // copy; BatchNorm's per-channel parameters stay) once the int8 path holds its own. The module then
  // refuses to run in float (a c10::Error saying so); nothing brings the kernel back.
  void release_float_kernel();
  bool float_kernel_released() const { return released_; }
  Conv2d conv{nullptr};
  SyncBatchNorm2d bn{nullptr};  // synchronised across processes in data-parallel training
  bool relu;
  bool upsampled;

 private:
  using ConvFn = std::function<torch::Tensor(const torch::Tensor&, const torch::Tensor&, const torch::Tensor&)>;
  // conv_fn(x, weight, bias) -> BatchNorm -> ReLU, or the folded conv -> ReLU.
  torch::Tensor conv_bn_relu(const torch::Tensor& x, const ConvFn& conv_fn);
  // The kernel times bn_scale() in the parameters' type (the folded kernel before any change of type).
  torch::Tensor scaled_kernel() const;
  // The folded kernel (in the folded type; w32 the same in float32) and the float32 bias -> the
  // oneDNN-blocked ones (none where oneDNN cannot run them).
  // `input`: the sizes of the first call's (channel-padded) input, which oneDNN picks the layout for.
  void prepack(const torch::Tensor& kernel, const torch::Tensor& w32, const torch::Tensor& b32,
               torch::IntArrayRef input);
  // The oneDNN kernels, made at the first call after folding (pack_once_), x that call's input.
  void prepack_once(const torch::Tensor& x);
  // `packed` applies to x (a CPU tensor of the folded type); a training module throws.
  bool uses_packed(const torch::Tensor& x, bool packed) const;
  torch::Tensor folded_weight_, folded_bias_;
  // oneDNN-blocked kernels (CPU, folded): the conv's, and forward_upsampled's four 2x2 phase kernels.
  torch::Tensor packed_weight_, packed_phase_weight_, packed_bias_, packed_phase_bias_;
  // float32 instead of packed_weight_ (models/prepacked_conv.h): oneDNN's prepacked convolution, the
  // ReLU fused, reading and writing channels-last activations as they lie.
  PrepackedConv packed_conv_;
  // Folded and not yet packed: the float32 kernel (bf16 folding only; float32 computes it from the
  // parameters) and bias the packing starts from.
  torch::Tensor pending_w32_, pending_b32_;
  bool pack_pending_ = false;  // set once when folding; read by every call (the tensors above are not)
  bool released_ = false;      // release_float_kernel()
  std::once_flag pack_once_;
};
TORCH_MODULE(ConvBn);

// Folds every ConvBn inside `module` (see ConvBnImpl::fold_batchnorm); returns how many.
int fold_batchnorm(torch::nn::Module& module, torch::Dtype dtype = torch::kFloat32);

}  // namespace geo
