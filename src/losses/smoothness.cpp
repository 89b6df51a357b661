#include "losses/smoothness.h"

namespace geo {

torch::Tensor edge_aware_smoothness(const torch::Tensor& map, const torch::Tensor& image) {
  TORCH_CHECK(map.dim() == 4, "map must be [B,C,H,W], got ", map.sizes());
  TORCH_CHECK(
      image.dim() == 4 && image.size(0) == map.size(0) && image.size(2) == map.size(2) && image.size(3) == map.size(3),
      "image ", image.sizes(), " must match map ", map.sizes(), " in batch, height, width");
  const auto W = map.size(3), H = map.size(2);
  auto dx = [W](const torch::Tensor& t) { return t.narrow(3, 0, W - 1) - t.narrow(3, 1, W - 1); };
  auto dy = [H](const torch::Tensor& t) { return t.narrow(2, 0, H - 1) - t.narrow(2, 1, H - 1); };
  const auto wx = torch::exp(-dx(image).abs().mean(1, true));
  const auto wy = torch::exp(-dy(image).abs().mean(1, true));
  // mean over (B, H, W) per channel, averaged over channels.
  const auto sx = (dx(map).abs() * wx).mean();
  const auto sy = (dy(map).abs() * wy).mean();
  return sx + sy;
}

}  // namespace geo
