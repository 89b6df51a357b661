#include "models/decoder.h"

#include "models/graph.h"

namespace geo {

namespace {
constexpr int64_t kDecoderWidths[6] = {512, 256, 128, 64, 32, 16};  // paper ("63" is a typo for 64)
}

EncoderDecoderImpl::EncoderDecoderImpl(const EncoderDecoderOptions& o, Head h) : options(o), head(std::move(h)) {
  encoder = register_module("encoder", ResNetEncoder(o.encoder));
  const auto& enc = encoder->channels();  // conv1, pool1, stage1..4
  int64_t in = enc[5];
  for (int k = 0; k < 6; ++k) {
    const int64_t width = kDecoderWidths[k];
    const std::string id = std::to_string(6 - k);  // GeoNet names: upconv6 ... upconv1
    upconv.push_back(register_module(
        "upconv" + id, ConvBn(in, width, 3, 1, true, /*upsampled=*/o.upsample == UpsampleMode::kNearest)));
    // Skip of decoder stage 6..2 is encoder feature 4..0; stage 1 has none.
    int64_t cat = width + (k < 5 ? enc[4 - k] : 0);
    if (k >= 3) cat += o.out_channels;  // upsampled coarser prediction (stages 3, 2, 1)
    iconv.push_back(register_module("iconv" + id, ConvBn(cat, width, 3)));
    if (o.fr_decoder) {
      FeatureRefinementOptions fo(width);
      fo.ratio = o.encoder.fr_ratio;
      fo.spatial_bn = o.encoder.fr_spatial_bn;
      refine.push_back(register_module("refined" + std::to_string(k + 5), FeatureRefinement(fo)));
    }
    if (k >= 2) {
      pred.push_back(register_module("pred" + std::to_string(6 - k),
                                     Conv2d(torch::nn::Conv2dOptions(width, o.out_channels, 3).padding(1))));
    }
    in = width;
  }
  init_weights(*this);
}

std::vector<torch::Tensor> EncoderDecoderImpl::forward(const torch::Tensor& x) {
  if (int8) return int8->forward(x);
  FloatOps ops;
  return encoder_decoder_graph(*this, ops, x);
}

}  // namespace geo
