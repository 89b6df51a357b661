#include "losses/photometric.h"

#include "geometry/checks.h"

namespace geo {

namespace {
torch::Tensor mean3x3(const torch::Tensor& x) {
  namespace F = torch::nn::functional;
  return F::avg_pool2d(x, F::AvgPool2dFuncOptions(3).stride(1).padding(1).count_include_pad(false));
}
}  // namespace

torch::Tensor ssim(const torch::Tensor& x, const torch::Tensor& y) {
  TORCH_CHECK(x.dim() == 4, "x must be [B,C,H,W], got ", x.sizes());
  TORCH_CHECK(x.sizes() == y.sizes(), "x ", x.sizes(), " and y ", y.sizes(), " must match");
  constexpr double C1 = 0.01 * 0.01;  // SSIM constants for [0,1] intensities (Wang et al., GeoNet)
  constexpr double C2 = 0.03 * 0.03;
  const auto mu_x = mean3x3(x), mu_y = mean3x3(y);
  const auto sigma_x = mean3x3(x * x) - mu_x * mu_x;
  const auto sigma_y = mean3x3(y * y) - mu_y * mu_y;
  const auto sigma_xy = mean3x3(x * y) - mu_x * mu_y;
  const auto n = (2 * mu_x * mu_y + C1) * (2 * sigma_xy + C2);
  const auto d = (mu_x * mu_x + mu_y * mu_y + C1) * (sigma_x + sigma_y + C2);
  return n / d;
}

torch::Tensor photometric_error_channels(const torch::Tensor& x, const torch::Tensor& y, double alpha) {
  TORCH_CHECK(alpha >= 0 && alpha <= 1, "alpha must be in [0,1], got ", alpha);
  const auto dssim = ((1 - ssim(x, y)) / 2).clamp(0, 1);
  return alpha * dssim + (1 - alpha) * (x - y).abs();
}

torch::Tensor photometric_error(const torch::Tensor& x, const torch::Tensor& y, double alpha) {
  return photometric_error_channels(x, y, alpha).mean(1, /*keepdim=*/true);
}

torch::Tensor channel_l2_norm(const torch::Tensor& x) {
  TORCH_CHECK(x.dim() == 4, "x must be [B,C,H,W], got ", x.sizes());
  torch::NoGradGuard no_grad;
  return x.square().sum(1, /*keepdim=*/true).sqrt_();
}

std::vector<torch::Tensor> image_pyramid(const torch::Tensor& image, int num_scales) {
  TORCH_CHECK(image.dim() == 4, "image must be [B,C,H,W], got ", image.sizes());
  const int64_t f = int64_t{1} << (num_scales - 1);
  TORCH_CHECK(image.size(2) % f == 0 && image.size(3) % f == 0, "image ", image.sizes(),
              ": height and width must be divisible by ", f, " for ", num_scales, " scales");
  std::vector<torch::Tensor> out{image};
  for (int s = 1; s < num_scales; ++s)
    out.push_back(torch::nn::functional::avg_pool2d(out.back(),
                                                    torch::nn::functional::AvgPool2dFuncOptions(2)));
  return out;
}

torch::Tensor masked_mean(const torch::Tensor& value, const torch::Tensor& mask) {
  TORCH_CHECK(value.dim() == 4, "value must be [B,C,H,W], got ", value.sizes());
  check_shape(mask, "mask", {value.size(0), 1, value.size(2), value.size(3)});
  const auto denom = (mask.sum() * value.size(1)).clamp_min(1e-12);
  return (value * mask).sum() / denom;
}

}  // namespace geo
