// int8 inference of the encoder-decoders (DepthNet, FlowNet) on the CPU: per-channel int8 weights
// (BatchNorm folded), uint8 activations in NHWC flowing from one convolution to the next, with
// quantized residual additions, pooling, upsampling and concatenations (LibTorch's quantized
// engine: oneDNN's where LibTorch has it); FR's gates are computed in float from pooled 8-bit
// features and applied to them in one pass; the predictions leave 8 bits before the head (sigmoid
// or flow scale), in float.
//
// Post-training calibration: observe(net) makes net's forward record the range of every quantized
// point while computing in float as before; run it on representative inputs, then quantize(net)
// fixes each point's scale and zero point from the ranges seen and prepacks the weights; from then
// on net's forward runs in int8 (inference only; the float weights stay for training and export).
#pragma once

#include <torch/torch.h>

#include <memory>
#include <string>
#include <vector>

namespace geo {

struct EncoderDecoderImpl;
struct FeatureRefinementImpl;

// LibTorch's quantized engine for int8 convolutions and products, selected process-wide: oneDNN's
// where this LibTorch has it, else x86's, FBGEMM's or QNNPACK's; "" when it has none.
std::string select_int8_engine();

// FR on an 8-bit NHWC feature q (quint8): the channel gate from q's max and mean over space, the
// spatial gate from the max and mean over the channels of q * a_c (both pooled from the 8-bit
// values), then q * a_c * a_s requantized to (scale, zero_point) in one pass; the gates themselves
// (MLP, 7x7 convolution, sigmoids) in float, as in the float network.
torch::Tensor int8_feature_refinement(FeatureRefinementImpl& fr, const torch::Tensor& q, double scale,
                                      int64_t zero_point);

class Int8EncoderDecoder {
 public:
  explicit Int8EncoderDecoder(EncoderDecoderImpl& net);
  ~Int8EncoderDecoder();
  // Observing: the float forward, recording ranges; quantized: the int8 forward.
  std::vector<torch::Tensor> forward(const torch::Tensor& x);
  // Ranges seen -> scales and zero points, weights quantized and prepacked. Throws when nothing was
  // observed or the engine cannot run a convolution.
  void quantize();
  bool quantized() const;
  int64_t points() const;  // quantized points (activations) of the network
  // The calibrated range (low, high) of each point [points,2]: what a model file keeps of the
  // calibration; set_ranges (before quantize, instead of observing) takes them back.
  torch::Tensor ranges() const;
  void set_ranges(const torch::Tensor& ranges);

  struct State;  // (models/int8.cpp)

 private:
  std::unique_ptr<State> state_;
};

// Starts calibrating `net` (in eval mode, BatchNorm folded): its forward records ranges from now on.
void observe_int8(EncoderDecoderImpl& net);
// Ends calibrating: net's forward runs in int8 from now on. Throws when net was not observed.
void quantize_int8(EncoderDecoderImpl& net);
// net in int8 with calibrated ranges kept from an earlier calibration (Int8EncoderDecoder::ranges);
// throws when they are not one per point of this network (checked by one call on a height x width input:
// the size the network will see).
void quantize_int8(EncoderDecoderImpl& net, const torch::Tensor& ranges, int64_t height, int64_t width);

}  // namespace geo
