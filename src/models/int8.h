// int8 inference of the networks (DepthNet, FlowNet, PoseNet) on the CPU: per-channel int8 weights
// (BatchNorm folded), uint8 activations in NHWC flowing from one convolution to the next, with
// quantized residual additions, pooling, upsampling and concatenations (LibTorch's quantized
// engine: oneDNN's where LibTorch has it); FR's gates are computed in float from pooled 8-bit
// features and applied to them in one pass; the predictions leave 8 bits before the head (sigmoid
// or flow scale), in float; the PoseNet's last convolution and its heads run in float.
//
// Post-training calibration: observe(net) makes net's forward record the range of every quantized
// point while computing in float as before; run it on representative inputs, then quantize(net)
// fixes each point's scale and zero point from the ranges seen and prepacks the weights; from then
// on net's forward runs in int8 (inference only; the float weights stay for training and export,
// unless quantize lets them go: Int8Graph::quantize).
#pragma once

#include <torch/torch.h>

#include "models/int8_engine.h"
#include "models/int8_kernels.h"

#include <map>
#include <memory>
#include <string>
#include <vector>

namespace geo {

struct Conv2dImpl;
struct ConvBnImpl;
struct EncoderDecoderImpl;
struct PoseNetImpl;

// What every int8 network shares: its quantized points (each calibrated range -> a scale and zero
// point), its prepacked int8 weights, and the two passes of its graph (models/int8.cpp).
class Int8Graph {
 public:
  virtual ~Int8Graph();
  // Ranges seen -> scales and zero points, weights quantized and prepacked. Throws when nothing was
  // observed or the engine cannot run a convolution. release_float (inference only): each layer that
  // runs in int8 lets go of its float kernel once its int8 one is made (ConvBnImpl::
  // release_float_kernel; the heads' too), so the network holds its kernels once; it then cannot run
  // in float again (nor be saved), even when quantizing fails part of the way.
  void quantize(bool release_float = false);
  bool quantized() const;
  int64_t points() const;  // quantized points (activations) of the network
  // The calibrated range (low, high) of each point [points,2]: what a model file keeps of the
  // calibration; set_ranges (before quantize, instead of observing) takes them back.
  torch::Tensor ranges() const;
  void set_ranges(const torch::Tensor& ranges);
  // The int8 kernels of a quantized network, by the layer's module name as in the network's state:
  // "<name>.weight" int8 [Co,Ci,k,k] (per output channel, symmetric), "<name>.scales" float64 [Co],
  // "<name>.bias" float32 [Co] (BatchNorm folded in); an upconv's 2x2 phase kernels under
  // "<name>.phases.": what an int8 model file keeps instead of the float kernels.
  std::map<std::string, torch::Tensor> kernels() const;
  // Before quantize (with set_ranges): quantize prepacks these kernels instead of quantizing the
  // float ones (which may then be absent, let go before the file was written). quantize checks them:
  // every layer's, of its shape, nothing else.
  void set_kernels(std::map<std::string, torch::Tensor> kernels);
  // quantize(release_float = true) was called: the layers that run in int8 hold no float kernel.
  bool float_released() const;
  // The quantized points the network's graph takes on an input like x (x's values are not read),
  // counted from the shapes alone: how many ranges a calibration of it holds.
  virtual int64_t graph_points(const torch::Tensor& x) = 0;

  struct State;  // (models/int8.cpp)

 protected:
  // net: the network whose BatchNorm-folded ConvBn layers run in int8; heads: its convolutions
  // without BatchNorm that run in int8 too; upconvs: its ConvBn layers after a nearest x2 upsampling
  // (their 2x2 phase kernels are packed as well); in_float: its ConvBn layers the graph runs in float
  // (neither packed nor let go).
  Int8Graph(torch::nn::Module& net, std::vector<Conv2dImpl*> heads, std::vector<ConvBnImpl*> upconvs,
            std::vector<ConvBnImpl*> in_float = {});
  // Observing: the float graph, recording ranges; quantized: the int8 graph. graph(ops, x) is the
  // network written once against either pass (models/int8.cpp).
  template <class Graph>
  std::vector<torch::Tensor> run(const torch::Tensor& x, Graph&& graph);

  std::unique_ptr<State> state_;
};

// The DepthNet's and FlowNet's encoder-decoder: its four predictions, as EncoderDecoderImpl::forward.
class Int8EncoderDecoder : public Int8Graph {
 public:
  explicit Int8EncoderDecoder(EncoderDecoderImpl& net);
  std::vector<torch::Tensor> forward(const torch::Tensor& x);
  int64_t graph_points(const torch::Tensor& x) override;

 private:
  EncoderDecoderImpl& net_;
};

// The PoseNet's convolutions: the normalised snippet [B,3L,H,W] -> conv7's features [B,256,h,w] in
// float; conv1..conv6 in int8, conv7 and the pose and camera heads (1x1) in float (1% of the
// multiply-adds, on a few pixels: what keeps the pose's accuracy).
class Int8PoseNet : public Int8Graph {
 public:
  explicit Int8PoseNet(PoseNetImpl& net);
  torch::Tensor forward(const torch::Tensor& x);
  int64_t graph_points(const torch::Tensor& x) override;

 private:
  PoseNetImpl& net_;
};

// Starts calibrating `net` (in eval mode, BatchNorm folded): its forward records ranges from now on.
void observe_int8(EncoderDecoderImpl& net);
void observe_int8(PoseNetImpl& net);
// Ends calibrating: net's forward runs in int8 from now on. Throws when net was not observed.
// release_float: see Int8Graph::quantize.
void quantize_int8(EncoderDecoderImpl& net, bool release_float = false);
void quantize_int8(PoseNetImpl& net, bool release_float = false);
// net in int8 with calibrated ranges kept from an earlier calibration (Int8Graph::ranges); throws,
// changing nothing, when they are not one per point of this network (Int8Graph::graph_points on a
// height x width input: the size the network will see). kernels: Int8Graph::kernels of the same network, prepacked as they
// are (none: quantized from the float weights).
void quantize_int8(EncoderDecoderImpl& net, const torch::Tensor& ranges, int64_t height, int64_t width,
                   bool release_float = false, const std::map<std::string, torch::Tensor>& kernels = {});
void quantize_int8(PoseNetImpl& net, const torch::Tensor& ranges, int64_t height, int64_t width,
                   bool release_float = false, const std::map<std::string, torch::Tensor>& kernels = {});

}  // namespace geo
