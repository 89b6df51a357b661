#include "losses/rigid_view.h"

#include "losses/photometric.h"

namespace geo {

OutOfView out_of_view(const LossConfig& cfg) {
  return cfg.sampler == Sampler::kBorder ? OutOfView::kBorder : OutOfView::kZero;
}

torch::Tensor to_loss_range(const torch::Tensor& image01, const LossConfig& cfg) {
  const double lo = cfg.image_range.at(0), hi = cfg.image_range.at(1);
  return lo == 0.0 && hi == 1.0 ? image01 : image01 * (hi - lo) + lo;
}

torch::Tensor from_loss_range(const torch::Tensor& image, const LossConfig& cfg) {
  const double lo = cfg.image_range.at(0), hi = cfg.image_range.at(1);
  return lo == 0.0 && hi == 1.0 ? image : (image - lo) / (hi - lo);
}

RigidView rigid_view(const torch::Tensor& src, const torch::Tensor& tgt, const torch::Tensor& flow,
                     const LossConfig& cfg) {
  RigidView v;
  v.warp = warp(src, flow, out_of_view(cfg));
  v.error_channels = photometric_error_channels(v.warp.image, tgt, cfg.ssim_alpha);
  return v;
}

}  // namespace geo
