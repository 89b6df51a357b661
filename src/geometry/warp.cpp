#include "geometry/warp.h"

#include "geometry/camera.h"
#include "core/tensor_checks.h"

namespace geo {

Warped warp(const torch::Tensor& image, const torch::Tensor& flow, OutOfView out_of_view) {
  TORCH_CHECK(image.dim() == 4, "image must be [B,C,H,W], got ", image.sizes());
  check_shape(flow, "flow", {image.size(0), 2, image.size(2), image.size(3)});
  const auto H = image.size(2), W = image.size(3);
  const auto coords = pixel_grid(H, W, flow.options()).narrow(1, 0, 2) + flow;  // [B,2,H,W]
  const auto x = coords.select(1, 0), y = coords.select(1, 1);
  // align_corners = true: -1 and 1 are the centres of the first and last pixels.
  const double sx = W > 1 ? 2.0 / static_cast<double>(W - 1) : 0.0;
  const double sy = H > 1 ? 2.0 / static_cast<double>(H - 1) : 0.0;
  const auto grid = torch::stack({x * sx - 1.0, y * sy - 1.0}, 3);  // [B,H,W,2]
  namespace F = torch::nn::functional;
  Warped out;
  out.image = F::grid_sample(
      image, grid.to(image.dtype()),
      F::GridSampleFuncOptions().mode(torch::kBilinear).padding_mode(torch::kBorder).align_corners(true));
  {
    torch::NoGradGuard no_grad;
    // GeoNet's sampler: the upper bounds are exclusive (a 1-pixel side keeps its one pixel).
    const auto inside = [](const torch::Tensor& c, int64_t n, bool exclusive) {
      return (c >= 0) & (exclusive && n > 1 ? c < n - 1 : c <= n - 1);
    };
    const bool zero = out_of_view == OutOfView::kZero;
    out.valid = (inside(x, W, zero) & inside(y, H, zero)).unsqueeze(1).to(image.dtype());
  }
  if (out_of_view == OutOfView::kZero) out.image = out.image * out.valid;
  return out;
}

}  // namespace geo
