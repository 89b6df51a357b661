// Building blocks shared by the networks (GeoNet / monodepth conventions).
#pragma once

#include "models/conv.h"

#include <torch/torch.h>

#include <functional>
#include <memory>
#include <string>

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

// conv (k x k, stride, symmetric padding k/2) -> BatchNorm -> ReLU (relu optional). The conv has
// no bias because BatchNorm follows (GeoNet's slim.conv2d with batch_norm).
struct ConvBnImpl : torch::nn::Module {
  ConvBnImpl(int64_t in, int64_t out, int64_t kernel, int64_t stride = 1, bool relu = true);
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
  // kernels) are also reordered once into oneDNN's blocked layout, so a call reorders only the
  // activations, not the weights (PyTorch's torch.utils.mkldnn; at::conv2d reorders the weights
  // on every call). Same results up to rounding.
  void fold_batchnorm(torch::Dtype dtype = torch::kFloat32);
  bool folded() const { return folded_weight_.defined(); }
  bool prepacked() const { return packed_weight_.defined(); }
  Conv2d conv{nullptr};
  torch::nn::BatchNorm2d bn{nullptr};
  bool relu;
  // Set: BatchNorm in training mode is sync_batch_norm over the processes `sync` sums over.
  std::shared_ptr<const SumAcrossProcesses> sync;

 private:
  using ConvFn = std::function<torch::Tensor(const torch::Tensor&, const torch::Tensor&, const torch::Tensor&)>;
  // conv_fn(x, weight, bias) -> BatchNorm -> ReLU, or the folded conv -> ReLU.
  torch::Tensor conv_bn_relu(const torch::Tensor& x, const ConvFn& conv_fn);
  // The folded float32 kernel and bias -> the oneDNN-blocked ones (none where oneDNN cannot run them).
  void prepack(const torch::Tensor& w32, const torch::Tensor& b32);
  // `packed` is defined and applies to x (a CPU tensor of the folded type); a training module throws.
  bool uses_packed(const torch::Tensor& x, const torch::Tensor& packed) const;
  torch::Tensor folded_weight_, folded_bias_;
  // oneDNN-blocked kernels (CPU, folded): the conv's, and forward_upsampled's four 2x2 phase kernels.
  torch::Tensor packed_weight_, packed_phase_weight_, packed_bias_, packed_phase_bias_;
};
TORCH_MODULE(ConvBn);

// conv2d(nearest ×2 upsampling of x, 3x3 weight, zero padding 1) without building the upsampled
// image. Output pixel (2i+a, 2j+b) only sees input rows {i-1, i} (a = 0) or {i, i+1} (a = 1), and
// likewise for columns, so each of the four phases (a, b) is a 2x2 convolution of x with summed
// taps (rows: a = 0 -> (w0, w1+w2), a = 1 -> (w0+w1, w2)). One conv of x with the four phase
// kernels stacked, then the phases interleaved. x [B,Ci,h,w], weight [Co,Ci,3,3], bias [Co] or
// undefined -> [B,Co,2h,2w]. Differentiable in x, weight and bias.
torch::Tensor conv3x3_of_upsampled(const torch::Tensor& x, const torch::Tensor& weight, const torch::Tensor& bias);

// Every ConvBn inside `module` normalises with statistics over all processes (`sum`) in training
// mode, or with its own batch's again (nullptr); returns how many.
int set_batchnorm_sync(torch::nn::Module& module, std::shared_ptr<const SumAcrossProcesses> sum);

// Folds every ConvBn inside `module` (see ConvBnImpl::fold_batchnorm); returns how many.
int fold_batchnorm(torch::nn::Module& module, torch::Dtype dtype = torch::kFloat32);

// x2 upsampling of the decoders.
enum class UpsampleMode { kNearest, kBilinear };  // nearest: GeoNet
torch::Tensor upsample2(const torch::Tensor& x, UpsampleMode mode);

// Resizes x to ref's height and width when they differ (GeoNet's resize_like; nearest).
torch::Tensor resize_like(const torch::Tensor& x, const torch::Tensor& ref);

// Weight initialisation of every network here: Xavier-uniform convolution weights and zero
// biases (TF-slim's default, which GeoNet uses), BatchNorm weight 1 and bias 0.
void init_weights(torch::nn::Module& module);

// BatchNorm convention of every BatchNorm2d inside `module`: epsilon and momentum (PyTorch's
// convention: running = (1 - momentum) * running + momentum * batch; TF-slim's decay d is
// momentum 1 - d). Call right after construction, before training or loading.
void set_batchnorm_style(torch::nn::Module& module, double eps, double momentum);

// The scale (gamma) parameters of every BatchNorm2d inside `module`: what stays fixed at 1 when the
// model does not learn BatchNorm scales (GeoNet's slim batch_norm has scale=False).
std::vector<torch::Tensor> batchnorm_scales(const torch::nn::Module& module);

// Number of scalar parameters.
int64_t count_parameters(const torch::nn::Module& module);

// Images in [0,1] -> [-1,1], the network input range of GeoNet.
torch::Tensor normalize_image(const torch::Tensor& image);

}  // namespace geo
