// Small helpers shared by the networks (GeoNet / monodepth conventions): decoder resizing, weight
// initialisation, BatchNorm conventions, parameter counts, the input range.
#pragma once

#include <torch/torch.h>

#include <vector>

namespace geo {

// x2 upsampling of the decoders.
enum class UpsampleMode { kNearest, kBilinear };  // nearest: GeoNet
torch::Tensor upsample2(const torch::Tensor& x, UpsampleMode mode);

// Resizes x to ref's height and width when they differ (GeoNet's resize_like; nearest).
torch::Tensor resize_like(const torch::Tensor& x, const torch::Tensor& ref);

// Weight initialisation of every network here: Xavier-uniform convolution weights and zero
// biases (TF-slim's default, which GeoNet uses), BatchNorm weight 1 and bias 0. Nothing while an
// UninitialisedWeights scope (models/conv.h) exists.
void init_weights(torch::nn::Module& module);

// BatchNorm convention of every BatchNorm (SyncBatchNorm2d) inside `module`: epsilon and momentum (PyTorch's
// convention: running = (1 - momentum) * running + momentum * batch; TF-slim's decay d is
// momentum 1 - d). Call right after construction, before training or loading.
void set_batchnorm_style(torch::nn::Module& module, double eps, double momentum);

// The scale (gamma) parameters of every BatchNorm (SyncBatchNorm2d) inside `module`: what stays fixed at 1 when the
// model does not learn BatchNorm scales (GeoNet's slim batch_norm has scale=False).
std::vector<torch::Tensor> batchnorm_scales(const torch::nn::Module& module);

// Number of scalar parameters.
int64_t count_parameters(const torch::nn::Module& module);

// Images in [0,1] -> [-1,1], the network input range of GeoNet.
torch::Tensor normalize_image(const torch::Tensor& image);

}  // namespace geo
