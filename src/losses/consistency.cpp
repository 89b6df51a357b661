#include "losses/consistency.h"

#include "core/tensor_checks.h"
#include "geometry/warp.h"
#include "losses/photometric.h"

namespace geo {

namespace {
void check_flow_pair(const torch::Tensor& fw, const torch::Tensor& bw, const char* bw_name) {
  check_shape(fw, "flow_fw", {-1, 2, -1, -1});
  check_shape(bw, bw_name, {fw.size(0), 2, fw.size(2), fw.size(3)});
}
// GeoNet's L2_norm: || |x| + 1e-10 ||_2 over the channel axis (used here without gradient).
torch::Tensor l2_norm(const torch::Tensor& x) { return channel_l2_norm(x.abs() + 1e-10); }
}  // namespace

torch::Tensor backward_at_forward(const torch::Tensor& flow_fw, const torch::Tensor& flow_bw, OutOfView out_of_view) {
  check_flow_pair(flow_fw, flow_bw, "flow_bw");
  return warp(flow_bw, flow_fw, out_of_view).image;
}

torch::Tensor visibility_mask(const torch::Tensor& flow_fw, const torch::Tensor& bw_at_fw, double alpha1,
                              double alpha2) {
  check_flow_pair(flow_fw, bw_at_fw, "bw_at_fw");
  torch::NoGradGuard no_grad;
  const auto sq = [](const torch::Tensor& f) { return (f * f).sum(1, true); };
  const auto lhs = sq(flow_fw + bw_at_fw);
  const auto rhs = alpha1 * (sq(flow_fw) + sq(bw_at_fw)) + alpha2;
  return (lhs < rhs).to(flow_fw.dtype());
}

Consistency geometric_consistency(const torch::Tensor& flow_fw, const torch::Tensor& bw_at_fw, double a, double b,
                                  int scale, bool scale_factor) {
  check_flow_pair(flow_fw, bw_at_fw, "bw_at_fw");
  const double k = scale_factor ? static_cast<double>(int64_t{1} << scale) : 1.0;
  const auto diff = (flow_fw + bw_at_fw).abs();
  Consistency out;
  {
    torch::NoGradGuard no_grad;
    const auto bound = (b * l2_norm(flow_fw) * k).clamp_min(a);
    out.mask = (l2_norm(diff) * k < bound).to(flow_fw.dtype());
  }
  out.loss = masked_mean(diff, out.mask);
  return out;
}

}  // namespace geo
