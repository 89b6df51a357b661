#include "models/int8.h"

#include <ATen/Parallel.h>
#include <ATen/core/dispatch/Dispatcher.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <unordered_map>
#include <utility>

#include "models/conv_bn.h"
#include "models/decoder.h"
#include "models/fr.h"
#include "models/graph.h"
#include "models/layers.h"
#include "models/pose_net.h"
#include "models/upsample_conv.h"

namespace geo {

namespace {

c10::OperatorHandle op(const char* name, const char* overload) {
  return c10::Dispatcher::singleton().findSchemaOrThrow(name, overload);
}

torch::Tensor call(const c10::OperatorHandle& handle, torch::jit::Stack stack) {
  handle.callBoxed(&stack);
  return stack.at(0).toTensor();
}

}  // namespace

struct Int8Graph::State {
  // A quantized point: the range its values took during calibration, then the scale and zero point
  // that map it onto 0..255 (the range widened to hold 0, as the zero padding of the next convolution
  // must be exact).
  struct Point {
    float lo = std::numeric_limits<float>::infinity(), hi = -std::numeric_limits<float>::infinity();
    double scale = 1.0;
    int64_t zero_point = 0;
    void see(const torch::Tensor& t) {
      lo = std::min(lo, t.min().item<float>());
      hi = std::max(hi, t.max().item<float>());
    }
    void fix() {
      const double l = std::min(0.0, static_cast<double>(lo));
      double h = std::max(0.0, static_cast<double>(hi));
      // A point that stayed (nearly) constant at 0 during calibration (a dead ReLU): any scale
      // represents it, but a tiny one makes oneDNN's requantization factors overflow.
      const double top = int8_reduced_range() ? 127.0 : 255.0;
      if (h - l < 1e-4) h = l + 1e-4 * top;
      scale = (h - l) / top;
      zero_point = std::clamp<int64_t>(std::llround(-l / scale), 0, static_cast<int64_t>(top));
    }
  };

  State(torch::nn::Module& n, std::vector<Conv2dImpl*> h, std::vector<ConvBnImpl*> u, std::vector<ConvBnImpl*> f)
      : net(n), heads(std::move(h)), upconvs(std::move(u)), in_float(std::move(f)) {}
  torch::nn::Module& net;
  std::vector<Conv2dImpl*> heads;
  std::vector<ConvBnImpl*> upconvs;
  std::vector<ConvBnImpl*> in_float;
  // The ConvBn layers that run in int8: every one of the network's but those in `in_float`.
  std::vector<ConvBnImpl*> int8_layers() const {
    std::vector<ConvBnImpl*> layers;
    for (const auto& m : net.modules(/*include_self=*/false))
      if (auto* cb = m->as<ConvBnImpl>(); cb && std::find(in_float.begin(), in_float.end(), cb) == in_float.end())
        layers.push_back(cb);
    return layers;
  }
  std::vector<Point> points;
  bool quantized = false;
  std::unordered_map<const torch::nn::Module*, c10::IValue> packed;
  std::unordered_map<const torch::nn::Module*, c10::IValue> packed_phases;  // the upconvs' 2x2 phase kernels
  std::optional<c10::OperatorHandle> conv, conv_relu, add_relu;
};

namespace {

// Float arithmetic (FloatOps) recording the range each quantized point takes.
struct Observe : FloatOps {
  static constexpr bool kShortcutFirst = false;  // the points' order (graph.h)
  std::vector<Int8Graph::State::Point>& points;
  size_t i = 0;
  explicit Observe(std::vector<Int8Graph::State::Point>& p) : points(p) {}
  torch::Tensor seen(torch::Tensor t) {
    if (i == points.size()) points.emplace_back();
    points[i++].see(t);
    return t;
  }
  torch::Tensor quantize(const torch::Tensor& x) { return seen(x); }
  torch::Tensor conv(ConvBnImpl& m, const torch::Tensor& x) { return seen(FloatOps::conv(m, x)); }
  torch::Tensor upconv(ConvBnImpl& m, const torch::Tensor& x, UpsampleMode mode) {
    return seen(FloatOps::upconv(m, x, mode));
  }
  torch::Tensor add_relu(const torch::Tensor& a, const torch::Tensor& b) { return seen(FloatOps::add_relu(a, b)); }
  torch::Tensor fr(FeatureRefinementImpl& m, const torch::Tensor& x) { return seen(FloatOps::fr(m, x)); }
  torch::Tensor cat(const std::vector<torch::Tensor>& parts) { return seen(FloatOps::cat(parts)); }
  torch::Tensor pred(Conv2dImpl& m, const torch::Tensor& x) { return seen(FloatOps::pred(m, x)); }
};

struct Quantized {
  static constexpr bool kShortcutFirst = false;  // the points' order (graph.h)
  Int8Graph::State& st;
  size_t i = 0;
  const Int8Graph::State::Point& next() {
    TORCH_CHECK(i < st.points.size(), "int8: ", st.points.size(), " quantized points for a network of more");
    return st.points[i++];
  }
  torch::Tensor quantize(const torch::Tensor& x) {
    const auto& p = next();
    return quantize_to_nhwc(x, p.scale, p.zero_point);
  }
  torch::Tensor conv_with(const c10::IValue& packed, const torch::Tensor& x, bool relu) {
    const auto& p = next();
    return call(relu ? *st.conv_relu : *st.conv, {x, packed, p.scale, p.zero_point});
  }
  torch::Tensor conv(ConvBnImpl& m, const torch::Tensor& x) { return conv_with(st.packed.at(&m), x, m.relu); }
  // Nearest x2 upsampling then m: as ConvBn::forward_upsampled, the four 2x2 phase convolutions at
  // x's resolution (2.25x fewer multiply-adds), the phases interleaved as bytes.
  torch::Tensor upconv(ConvBnImpl& m, const torch::Tensor& x, UpsampleMode mode) {
    const auto phases = st.packed_phases.find(&m);
    if (mode != UpsampleMode::kNearest || phases == st.packed_phases.end() ||
        x.size(2) * x.size(3) < ConvBnImpl::kMinSubpixelArea)
      return conv(m, upsample2(x, mode));
    return interleave_phases_int8(conv_with(phases->second, x, m.relu), m.conv->options.out_channels());
  }
  torch::Tensor add_relu(const torch::Tensor& a, const torch::Tensor& b) {
    const auto& p = next();
    return call(*st.add_relu, {a, b, p.scale, p.zero_point});
  }
  torch::Tensor fr(FeatureRefinementImpl& m, const torch::Tensor& x) {
    const auto& p = next();
    return int8_feature_refinement(m, x, p.scale, p.zero_point);
  }
  torch::Tensor cat(const std::vector<torch::Tensor>& parts) {
    const auto& p = next();
    return cat_int8(parts, p.scale, p.zero_point);
  }
  torch::Tensor pred(Conv2dImpl& m, const torch::Tensor& y) {
    return dequantize(conv_with(st.packed.at(&m), y, false));
  }
  torch::Tensor dequantize(const torch::Tensor& y) { return y.dequantize().contiguous(); }
};

// w [Co,Ci,k,k] float (times factor [Co] per output channel, when given) -> int8 per output
// channel (symmetric), prepacked with its float bias.
c10::IValue pack(const torch::Tensor& weight, const torch::Tensor& bias, int64_t stride, int64_t padding,
                 const torch::Tensor& factor = {}) {
  const auto qw = quantize_weight_per_channel(weight, factor);
  torch::jit::Stack stack{qw,
                          bias.defined() ? c10::IValue(bias.to(torch::kFloat32)) : c10::IValue(),
                          std::vector<int64_t>{stride, stride},
                          std::vector<int64_t>{padding, padding},
                          std::vector<int64_t>{1, 1},
                          int64_t{1}};
  op("quantized::conv2d_prepack", "").callBoxed(&stack);
  return stack.at(0);
}

}  // namespace

Int8Graph::Int8Graph(torch::nn::Module& net, std::vector<Conv2dImpl*> heads, std::vector<ConvBnImpl*> upconvs,
                     std::vector<ConvBnImpl*> in_float)
    : state_(std::make_unique<State>(net, std::move(heads), std::move(upconvs), std::move(in_float))) {}
Int8Graph::~Int8Graph() = default;

bool Int8Graph::quantized() const { return state_->quantized; }
int64_t Int8Graph::points() const { return static_cast<int64_t>(state_->points.size()); }

template <class Graph>
std::vector<torch::Tensor> Int8Graph::run(const torch::Tensor& x, Graph&& graph) {
  TORCH_CHECK(!state_->net.is_training(), "int8: the network is in training mode (int8 is for inference)");
  torch::NoGradGuard no_grad;
  const auto input = x.to(torch::kFloat32);
  if (state_->quantized) {
    TORCH_CHECK(x.device().is_cpu(), "int8 inference runs on the CPU, got an input on ", x.device());
    Quantized ops{*state_};
    auto out = graph(ops, input);
    TORCH_CHECK(ops.i == state_->points.size(), "int8: ", state_->points.size(), " quantized points for a network of ",
                ops.i);
    return out;
  }
  Observe ops{state_->points};
  auto out = graph(ops, input);
  TORCH_CHECK(ops.i == state_->points.size(), "int8: the graph changed between calibration inputs");
  return out;
}

namespace {
std::vector<Conv2dImpl*> heads_of(EncoderDecoderImpl& net) {
  std::vector<Conv2dImpl*> heads;
  for (auto& p : net.pred) heads.push_back(p.get());
  return heads;
}
std::vector<ConvBnImpl*> upconvs_of(EncoderDecoderImpl& net) {
  std::vector<ConvBnImpl*> upconvs;
  if (net.options.upsample == UpsampleMode::kNearest)
    for (auto& u : net.upconv) upconvs.push_back(u.get());
  return upconvs;
}
}  // namespace

Int8EncoderDecoder::Int8EncoderDecoder(EncoderDecoderImpl& net)
    : Int8Graph(net, heads_of(net), upconvs_of(net)), net_(net) {}

std::vector<torch::Tensor> Int8EncoderDecoder::forward(const torch::Tensor& x) {
  return run(x, [this](auto& ops, const torch::Tensor& in) { return encoder_decoder_graph(net_, ops, in); });
}

// (pose_graph runs the last convolution in float)
Int8PoseNet::Int8PoseNet(PoseNetImpl& net) : Int8Graph(net, {}, {}, {net.convs.back().get()}), net_(net) {}

torch::Tensor Int8PoseNet::forward(const torch::Tensor& x) {
  return run(x, [this](auto& ops,
                       const torch::Tensor& in) { return std::vector<torch::Tensor>{pose_graph(net_, ops, in)}; })
      .at(0);
}

void Int8Graph::quantize(bool release_float) {
  auto& st = *state_;
  TORCH_CHECK(!st.points.empty(), "int8: nothing was observed: run the network on calibration inputs first");
  TORCH_CHECK(!select_int8_engine().empty(), "int8: this LibTorch has no quantized engine");
  for (auto& p : st.points) p.fix();
  st.conv = op("quantized::conv2d", "new");
  st.conv_relu = op("quantized::conv2d_relu", "new");
  st.add_relu = op("quantized::add_relu", "");
  torch::NoGradGuard no_grad;
  // Layer by layer, so that with release_float each float kernel goes as its int8 one comes (the
  // int8 kernels take the memory the float ones leave: the peak stays the float model's).
  for (auto* cb : st.int8_layers()) {
    TORCH_CHECK(cb->folded(), "int8: BatchNorm must be folded before quantizing");
    const auto& o = cb->conv->options;
    // The folded kernel quantized from the weight and BatchNorm's factor, not made in float.
    st.packed[cb] =
        pack(cb->conv->weight, cb->folded_bias(), (*o.stride())[0], (*o.kernel_size())[0] / 2, cb->bn_scale());
    if (std::find(st.upconvs.begin(), st.upconvs.end(), cb) != st.upconvs.end())
      st.packed_phases[cb] = pack(phase_kernels(cb->folded_weight().to(torch::kFloat32)),
                                  cb->folded_bias().to(torch::kFloat32).repeat({4}), 1, 1);
    if (release_float) cb->release_float_kernel();
  }
  for (auto* h : st.heads) {
    const auto& o = h->options;
    st.packed[h] = pack(h->weight, h->bias, (*o.stride())[0], (*o.kernel_size())[0] / 2);
    if (release_float) h->weight.set_data(torch::empty({0}, h->weight.options()));
  }
  st.quantized = true;
}

torch::Tensor Int8Graph::ranges() const {
  auto r = torch::empty({points(), 2}, torch::kFloat32);
  auto a = r.accessor<float, 2>();
  for (int64_t i = 0; i < points(); ++i) a[i][0] = state_->points[i].lo, a[i][1] = state_->points[i].hi;
  return r;
}

void Int8Graph::set_ranges(const torch::Tensor& ranges) {
  TORCH_CHECK(!state_->quantized && state_->points.empty(), "int8: ranges are set on a network not yet calibrated");
  TORCH_CHECK(ranges.dim() == 2 && ranges.size(1) == 2 && ranges.size(0) > 0, "int8: ranges must be [points,2], got ",
              ranges.sizes());
  const auto r = ranges.to(torch::kFloat32).contiguous();
  TORCH_CHECK(torch::isfinite(r).all().item<bool>(), "int8: the ranges hold a non-finite value");
  auto a = r.accessor<float, 2>();
  for (int64_t i = 0; i < r.size(0); ++i) {
    TORCH_CHECK(a[i][0] <= a[i][1], "int8: range ", i, " has its low end above its high end");
    state_->points.emplace_back();
    state_->points.back().lo = a[i][0];
    state_->points.back().hi = a[i][1];
  }
}

namespace {

template <class Int8Net, class Net>
void quantize_with_ranges(Net& net, const torch::Tensor& ranges, const torch::Tensor& probe, bool release_float) {
  auto int8 = std::make_shared<Int8Net>(net);
  int8->set_ranges(ranges);
  int8->quantize(release_float);
  // One call checks that the ranges are this network's (one per point). At the network's own input
  // size: LibTorch 1.13's oneDNN int8 convolutions, on 2 threads, failed ("could not create a
  // primitive descriptor for a reorder primitive") on a 2x7 input after a first call on 2x2.
  net.int8 = int8;
  try {
    torch::NoGradGuard no_grad;
    int8->forward(probe);
  } catch (...) {
    net.int8.reset();
    throw;
  }
}

template <class Net>
void quantize_observed(Net& net, bool release_float) {
  TORCH_CHECK(net.int8, "int8: the network was not observed (observe_int8) before quantize_int8");
  net.int8->quantize(release_float);
}

}  // namespace

void observe_int8(EncoderDecoderImpl& net) { net.int8 = std::make_shared<Int8EncoderDecoder>(net); }
void observe_int8(PoseNetImpl& net) { net.int8 = std::make_shared<Int8PoseNet>(net); }
void quantize_int8(EncoderDecoderImpl& net, bool release_float) { quantize_observed(net, release_float); }
void quantize_int8(PoseNetImpl& net, bool release_float) { quantize_observed(net, release_float); }

void quantize_int8(EncoderDecoderImpl& net, const torch::Tensor& ranges, int64_t height, int64_t width,
                   bool release_float) {
  quantize_with_ranges<Int8EncoderDecoder>(
      net, ranges, torch::zeros({1, net.encoder->options.in_channels, height, width}), release_float);
}

void quantize_int8(PoseNetImpl& net, const torch::Tensor& ranges, int64_t height, int64_t width, bool release_float) {
  quantize_with_ranges<Int8PoseNet>(net, ranges, torch::zeros({1, 3 * net.options.seq_length, height, width}),
                                    release_float);
}

}  // namespace geo
