// Building blocks shared by the networks (GeoNet / monodepth conventions).
#pragma once

#include <torch/torch.h>

#include <string>

namespace geo {

// conv (k x k, stride, symmetric padding k/2) -> BatchNorm -> ReLU (relu optional). The conv has
// no bias because BatchNorm follows (GeoNet's slim.conv2d with batch_norm).
struct ConvBnImpl : torch::nn::Module {
  ConvBnImpl(int64_t in, int64_t out, int64_t kernel, int64_t stride = 1, bool relu = true);
  torch::Tensor forward(const torch::Tensor& x);
  torch::nn::Conv2d conv{nullptr};
  torch::nn::BatchNorm2d bn{nullptr};
  bool relu;
};
TORCH_MODULE(ConvBn);

// x2 upsampling: "nearest" (GeoNet) or "bilinear".
torch::Tensor upsample2(const torch::Tensor& x, const std::string& mode);

// Resizes x to ref's height and width when they differ (GeoNet's resize_like; nearest).
torch::Tensor resize_like(const torch::Tensor& x, const torch::Tensor& ref);

// Weight initialisation of every network here: Xavier-uniform convolution weights and zero
// biases (TF-slim's default, which GeoNet uses), BatchNorm weight 1 and bias 0.
void init_weights(torch::nn::Module& module);

// Number of scalar parameters.
int64_t count_parameters(const torch::nn::Module& module);

// Images in [0,1] -> [-1,1], the network input range of GeoNet.
torch::Tensor normalize_image(const torch::Tensor& image);

}  // namespace geo
