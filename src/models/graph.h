// The networks' forward passes, written once over an operations policy `Ops`: FloatOps (below)
// computes in float (the networks' forward), int8.cpp's Observe computes in float while recording
// the range of every quantized point (int8 calibration), its Quantized computes in int8. An
// architecture change (a block, a skip, a layer's place) is one edit here; the modules' constructors
// define the layers' shapes.
//
// Each call of `ops` that quantizes (quantize, conv, upconv, add_relu, fr, cat, pred) takes the next
// quantized point, in the order the calls are made: statements, never two such calls in one
// expression (C++ leaves their order open). The order is stored with an int8 model's calibration:
// changing it is a change of the model file's format.
#pragma once

#include <torch/torch.h>

#include <vector>

#include "models/conv_bn.h"
#include "models/decoder.h"
#include "models/fr.h"
#include "models/layers.h"
#include "models/pose_net.h"
#include "models/resnet_encoder.h"

namespace geo {

// Float arithmetic: each operation as the modules compute it.
struct FloatOps {
  // A residual block's shortcut is computed before its body: the order the float networks have
  // always computed it in, which fixes the order autograd sums the block input's gradients in (a
  // different order changes training's rounding, and 400 iterations later its result). The int8
  // policies take the body first: their quantized points are numbered in that order.
  static constexpr bool kShortcutFirst = true;
  torch::Tensor quantize(const torch::Tensor& x) { return x; }
  torch::Tensor dequantize(const torch::Tensor& x) { return x; }
  torch::Tensor conv(ConvBnImpl& m, const torch::Tensor& x) { return m.forward(x); }
  // GeoNet's upconv: x2 upsampling, then m (nearest: computed at x's resolution, ConvBn::forward_upsampled).
  torch::Tensor upconv(ConvBnImpl& m, const torch::Tensor& x, UpsampleMode mode) {
    return mode == UpsampleMode::kNearest ? m.forward_upsampled(x) : m.forward(upsample2(x, mode));
  }
  // Inference on the CPU: one fused pass, in place over `a` (the block's own output, which nothing
  // else holds); the same numbers as relu(a + b).
  torch::Tensor add_relu(const torch::Tensor& a, const torch::Tensor& b) {
    if (torch::GradMode::is_enabled() || !a.is_cpu() || a.scalar_type() != torch::kFloat32 || a.sizes() != b.sizes())
      return torch::relu(a + b);
    auto out = a;
    return at::_add_relu_(out, b);
  }
  torch::Tensor fr(FeatureRefinementImpl& m, const torch::Tensor& x) { return m.forward(x); }
  // Inference on the CPU where the first part is channels-last (the prepacked float convolutions
  // read and write that order): the result in it too, so that the next convolution reads it as it
  // lies, each part copied into its channels (LibTorch's channels-last cat copies a pixel's channels
  // part by part: 4-6x slower beside a one-channel part).
  torch::Tensor cat(const std::vector<torch::Tensor>& parts) {
    if (torch::GradMode::is_enabled() || !parts[0].is_cpu() || parts[0].dim() != 4 ||
        !parts[0].is_contiguous(at::MemoryFormat::ChannelsLast))
      return torch::cat(parts, 1);
    int64_t channels = 0;
    for (const auto& p : parts) channels += p.size(1);
    const auto& first = parts[0];
    auto out = torch::empty({first.size(0), channels, first.size(2), first.size(3)},
                            first.options().memory_format(at::MemoryFormat::ChannelsLast));
    int64_t at = 0;
    for (const auto& p : parts) {
      out.narrow(1, at, p.size(1)).copy_(p);
      at += p.size(1);
    }
    return out;
  }
  // A prediction head (a plain convolution, float output).
  torch::Tensor pred(Conv2dImpl& m, const torch::Tensor& x) { return m.forward(x); }
};

// GeoNet's resconv (BottleneckImpl): 1x1 -> 3x3/stride -> 1x1 + projection shortcut, then ReLU.
template <class Ops>
torch::Tensor bottleneck_graph(BottleneckImpl& b, Ops& ops, const torch::Tensor& x) {
  torch::Tensor shortcut;
  if constexpr (Ops::kShortcutFirst) shortcut = ops.conv(*b.proj, x);
  auto r = ops.conv(*b.c1, x);
  r = ops.conv(*b.c2, r);
  r = ops.conv(*b.c3, r);
  if constexpr (!Ops::kShortcutFirst) shortcut = ops.conv(*b.proj, x);
  return ops.add_relu(r, shortcut);
}

// ResNet-18/34's basic block (BasicBlockImpl): 3x3/stride -> 3x3 + shortcut, then ReLU.
template <class Ops>
torch::Tensor basic_block_graph(BasicBlockImpl& b, Ops& ops, const torch::Tensor& x) {
  torch::Tensor shortcut;
  if constexpr (Ops::kShortcutFirst) shortcut = b.proj ? ops.conv(*b.proj, x) : x;
  auto r = ops.conv(*b.c1, x);
  r = ops.conv(*b.c2, r);
  if constexpr (!Ops::kShortcutFirst) shortcut = b.proj ? ops.conv(*b.proj, x) : x;
  return ops.add_relu(r, shortcut);
}

// The ResNet encoder (ResNetEncoderImpl) on x, which `ops` has already taken in (quantized): six
// features, conv1 (1/2), pool1 (1/4), stage1..4 each followed by its FR.
template <class Ops>
std::vector<torch::Tensor> encoder_graph(ResNetEncoderImpl& enc, Ops& ops, const torch::Tensor& x) {
  TORCH_CHECK(x.dim() == 4 && x.size(1) == enc.options.in_channels, "encoder input must be [B,",
              enc.options.in_channels, ",H,W], got ", x.sizes());
  std::vector<torch::Tensor> feats;
  feats.push_back(ops.conv(*enc.conv1, x));
  // (Max-pooling keeps a quantized tensor's scale: no point of its own, the same call for every Ops.)
  feats.push_back(torch::max_pool2d(feats.back(), {3, 3}, {2, 2}, {1, 1}, {1, 1}));
  for (size_t s = 0; s < enc.stages.size(); ++s) {
    auto y = feats.back();
    for (const auto& m : enc.stages[s]->children()) {
      if (auto* b = m->as<BottleneckImpl>()) {
        y = bottleneck_graph(*b, ops, y);
      } else if (auto* bb = m->as<BasicBlockImpl>()) {
        y = basic_block_graph(*bb, ops, y);
      } else {
        TORCH_CHECK(false, "unknown block in the encoder's stage ", s + 1);
      }
    }
    if (!enc.refine.empty()) y = ops.fr(*enc.refine[s], y);
    feats.push_back(y);
  }
  return feats;
}

// The encoder-decoder (DepthNet, FlowNet: EncoderDecoderImpl) on the float input x: the four
// predictions, finest first. Decoder stage k (GeoNet's upconv6..1): upconv of the coarser stage, its
// encoder skip (stages 6..2), the coarser prediction upsampled (stages 3..1), concatenated, iconv,
// FR; stages 4..1 predict.
template <class Ops>
std::vector<torch::Tensor> encoder_decoder_graph(EncoderDecoderImpl& net, Ops& ops, const torch::Tensor& x) {
  const auto input = ops.quantize(x);
  const auto feats = encoder_graph(*net.encoder, ops, input);
  const auto mode = net.options.upsample;
  std::vector<torch::Tensor> preds;  // coarsest first while building
  auto y = feats[5];
  for (int k = 0; k < 6; ++k) {
    const torch::Tensor& ref = k < 5 ? feats[4 - k] : x;  // stage 1 resizes to the input size
    std::vector<torch::Tensor> parts;  // (not an initializer list: GCC 12 -Warray-bounds false positive)
    parts.reserve(3);
    parts.push_back(resize_like(ops.upconv(*net.upconv[k], y, mode), ref));
    if (k < 5) parts.push_back(feats[4 - k]);
    if (k >= 3) parts.push_back(ops.quantize(resize_like(upsample2(preds.back(), mode), ref)));
    y = ops.cat(parts);
    y = ops.conv(*net.iconv[k], y);
    if (!net.refine.empty()) y = ops.fr(*net.refine[k], y);
    if (k >= 2) preds.push_back(net.head(ops.pred(*net.pred[k - 2], y)));
  }
  // In the dense layout whatever the layers computed in (prepacked float convolutions: channels-last).
  return {preds[3].contiguous(), preds[2].contiguous(), preds[1].contiguous(), preds[0].contiguous()};
}

// The PoseNet's convolutions (PoseNetImpl::convs) on the normalised snippet x: the features its
// heads read. The last convolution stays in float (1% of the multiply-adds: 256 channels on a few
// pixels): 8 bits at its output, which the heads average, moved the learning check's ATE by +8%
// (float: -2%).
template <class Ops>
torch::Tensor pose_graph(PoseNetImpl& net, Ops& ops, const torch::Tensor& x) {
  auto y = ops.quantize(x);
  for (size_t i = 0; i + 1 < net.convs.size(); ++i) y = ops.conv(*net.convs[i], y);
  return net.convs.back()->forward(ops.dequantize(y));
}

}  // namespace geo
