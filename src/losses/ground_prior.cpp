#include "losses/ground_prior.h"

#include "core/tensor_checks.h"

#include <cmath>
#include <limits>

namespace geo {

torch::Tensor ground_prior(const torch::Tensor& disp, const torch::Tensor& K, double tolerance, double max_heights) {
  check_shape(disp, "disp", {-1, 1, -1, -1});
  const int64_t B = disp.size(0), H = disp.size(2), W = disp.size(3);
  check_shape(K, "K", {B, 3, 3});
  TORCH_CHECK(tolerance >= 0 && tolerance < 1, "ground_prior: tolerance must be in [0, 1), got ", tolerance);
  TORCH_CHECK(max_heights > 0, "ground_prior: max_heights must be > 0, got ", max_heights);
  const auto opts = disp.options();
  const auto Kd = K.detach().to(opts.dtype());
  // (v - cy) / fy per image and row: the road's height below the camera per unit of depth.
  const auto rows = torch::arange(H, opts).view({1, H});
  const auto slope = (rows - Kd.select(1, 1).select(1, 2).view({B, 1})) / Kd.select(1, 1).select(1, 1).view({B, 1});
  const auto below = slope > 1.0 / max_heights;  // [B,H] rows bounded
  const auto top = static_cast<double>(std::floor(static_cast<double>(H) * (1.0 - kGroundRows)));
  const auto lower = (rows >= top).expand({B, H}) & below;
  // The camera's height in the prediction's unit: the median of slope x depth over the lower rows
  // (exact on the road, lower on things in front of it: the road's as long as it is half of them).
  torch::Tensor height;
  {
    torch::NoGradGuard no_grad;
    const auto y = slope.view({B, H, 1}) / disp.detach().squeeze(1).clamp_min(1e-6);  // [B,H,W]
    const auto masked = torch::where(lower.view({B, H, 1}).expand({B, H, W}), y,
                                     torch::full_like(y, std::numeric_limits<double>::quiet_NaN()));
    height = std::get<0>(masked.flatten(1).nanmedian(1));  // [B]; NaN where no lower row is bounded
  }
  const auto has_rows = lower.any(1);                                  // [B]
  height = torch::where(has_rows, height, torch::ones_like(height));   // no NaN into the gradient
  const auto road = (slope / height.view({B, 1})).view({B, 1, H, 1});  // the road's disparity per row
  const auto bounded = (below & has_rows.view({B, 1})).view({B, 1, H, 1}).expand_as(disp);
  const auto penalty = torch::relu(1.0 - tolerance - disp / road.clamp_min(1e-12));
  const auto weight = bounded.to(disp.dtype());
  return (penalty * weight).sum() / weight.sum().clamp_min(1.0);
}

}  // namespace geo
