#include "losses/depth_anchor.h"

#include "core/tensor_checks.h"

namespace geo {
namespace {

// log(depth / its per-image mean) from a disparity [B,1,H,W].
torch::Tensor log_relative_depth(const torch::Tensor& disp) {
  const auto depth = disp.reciprocal();
  return depth.log() - depth.mean({1, 2, 3}, true).log();
}

}  // namespace

torch::Tensor depth_anchor(const torch::Tensor& disp, const torch::Tensor& teacher_disp) {
  check_shape(disp, "depth_anchor: disp", {-1, 1, -1, -1});
  check_shape(teacher_disp, "depth_anchor: teacher_disp", {disp.size(0), 1, disp.size(2), disp.size(3)});
  return (log_relative_depth(disp) - log_relative_depth(teacher_disp.detach())).abs().mean();
}

}  // namespace geo
