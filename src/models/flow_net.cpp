#include "models/flow_net.h"

#include "core/tensor_checks.h"

namespace geo {

torch::Tensor flow_net_input(const torch::Tensor& tgt, const torch::Tensor& src, const torch::Tensor& rigid_warp,
                             const torch::Tensor& rigid_flow, const torch::Tensor& rigid_error_norm) {
  check_shape(tgt, "tgt", {-1, 3, -1, -1});
  const auto B = tgt.size(0), H = tgt.size(2), W = tgt.size(3);
  check_shape(src, "src", {B, 3, H, W});
  check_shape(rigid_warp, "rigid_warp", {B, 3, H, W});
  check_shape(rigid_flow, "rigid_flow", {B, 2, H, W});
  check_shape(rigid_error_norm, "rigid_error_norm", {B, 1, H, W});
  return torch::cat(
      {normalize_image(tgt), normalize_image(src), normalize_image(rigid_warp), rigid_flow, rigid_error_norm}, 1);
}

FlowNetImpl::FlowNetImpl(const FlowNetOptions& o) : options(o) {
  const double scale = o.flow_scale;
  net = register_module("net", EncoderDecoder(encoder_decoder_options(o.backbone, 12, 2),
                                              [scale](const torch::Tensor& x) { return scale * x; }));
  if (o.zero_init_residual) {
    torch::NoGradGuard no_grad;
    for (auto& p : net->pred) {
      p->weight.zero_();
      if (p->bias.defined()) p->bias.zero_();
    }
  }
}

FlowOutput FlowNetImpl::forward(const torch::Tensor& input) {
  TORCH_CHECK(input.dim() == 4 && input.size(1) == 12, "FlowNet input must be [B,12,H,W], got ", input.sizes());
  FlowOutput out;
  for (auto f : net(input.to(compute_dtype))) {
    f = f.to(torch::kFloat32);
    // Normalised flow -> pixels of its scale: u * W_s, v * H_s (GeoNet). Scalar products, not a
    // factor tensor made from host values: that would be a host-to-device copy (a wait) per scale.
    out.flow.push_back(torch::cat(
        {f.narrow(1, 0, 1) * static_cast<double>(f.size(3)), f.narrow(1, 1, 1) * static_cast<double>(f.size(2))}, 1));
  }
  return out;
}

}  // namespace geo
