#include "models/depth_net.h"

namespace geo {

EncoderDecoderOptions encoder_decoder_options(const DepthNetOptions& o, int64_t in, int64_t out) {
  EncoderDecoderOptions e;
  e.encoder.in_channels = in;
  e.encoder.depth = o.encoder_depth;
  e.encoder.use_fr = o.use_fr && o.fr_encoder;
  e.encoder.fr_ratio = o.fr_ratio;
  e.encoder.fr_spatial_bn = o.fr_spatial_bn;
  e.out_channels = out;
  e.fr_decoder = o.use_fr && o.fr_decoder;
  e.upsample = o.upsample;
  return e;
}

DepthNetImpl::DepthNetImpl(const DepthNetOptions& o) : options(o) {
  const double scale = o.disp_scale, min_disp = o.min_disp;
  net = register_module("net",
                        EncoderDecoder(encoder_decoder_options(o, 3, 1), [scale, min_disp](const torch::Tensor& x) {
                          return scale * torch::sigmoid(x) + min_disp;
                        }));
}

DepthOutput DepthNetImpl::forward(const torch::Tensor& image) {
  TORCH_CHECK(image.dim() == 4 && image.size(1) == 3, "DepthNet input must be [B,3,H,W], got ", image.sizes());
  auto disp = net(normalize_image(image.to(compute_dtype)));
  for (auto& d : disp) d = d.to(torch::kFloat32);
  return DepthOutput{std::move(disp)};
}

}  // namespace geo
