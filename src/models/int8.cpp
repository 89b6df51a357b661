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
#include "models/int8_engine.h"
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
  bool released = false;                       // quantize(release_float = true)
  std::map<std::string, torch::Tensor> given;  // set_kernels: taken by quantize
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

// Shapes alone: counts the quantized points the graph takes (one range each in a calibration),
// every operation giving an uninitialised tensor of its result's shape; nothing is computed but the
// few float steps between them (pooling, resizing, the heads, the PoseNet's last convolution).
struct Count {
  static constexpr bool kShortcutFirst = false;  // (the count does not depend on it)
  size_t i = 0;
  torch::Tensor conv_shaped(const torch::nn::detail::ConvNdOptions<2>& o, const torch::Tensor& x) {
    ++i;
    const int64_t s = (*o.stride())[0];  // (k x k, padding k/2, k odd)
    return torch::empty({x.size(0), o.out_channels(), (x.size(2) - 1) / s + 1, (x.size(3) - 1) / s + 1});
  }
  torch::Tensor quantize(const torch::Tensor& x) { return ++i, x; }
  torch::Tensor dequantize(const torch::Tensor& x) { return torch::zeros_like(x); }  // (into a float layer)
  torch::Tensor conv(ConvBnImpl& m, const torch::Tensor& x) { return conv_shaped(m.conv->options, x); }
  torch::Tensor upconv(ConvBnImpl& m, const torch::Tensor& x, UpsampleMode) {
    ++i;
    return torch::empty({x.size(0), m.conv->options.out_channels(), 2 * x.size(2), 2 * x.size(3)});
  }
  torch::Tensor add_relu(const torch::Tensor& a, const torch::Tensor&) { return ++i, a; }
  torch::Tensor fr(FeatureRefinementImpl&, const torch::Tensor& x) { return ++i, x; }
  torch::Tensor cat(const std::vector<torch::Tensor>& parts) {
    ++i;
    int64_t channels = 0;
    for (const auto& p : parts) channels += p.size(1);
    return torch::empty({parts[0].size(0), channels, parts[0].size(2), parts[0].size(3)});
  }
  torch::Tensor pred(Conv2dImpl& m, const torch::Tensor& x) { return conv_shaped(m.options, x); }
};

// w qint8 [Co,Ci,k,k] per output channel (zero points 0) and its float bias -> prepacked (a 1x1
// kernel as a dilated one where int8_dilated_1x1 says).
c10::IValue prepack(const torch::Tensor& qweight, const torch::Tensor& bias, int64_t stride, int64_t padding) {
  const int64_t dilation = qweight.size(2) == 1 && qweight.size(3) == 1 && int8_dilated_1x1() ? 2 : 1;
  torch::jit::Stack stack{qweight,
                          bias.defined() ? c10::IValue(bias.to(torch::kFloat32)) : c10::IValue(),
                          std::vector<int64_t>{stride, stride},
                          std::vector<int64_t>{padding, padding},
                          std::vector<int64_t>{dilation, dilation},
                          int64_t{1}};
  op("quantized::conv2d_prepack", "").callBoxed(&stack);
  return stack.at(0);
}

// w [Co,Ci,k,k] float (times factor [Co] per output channel, when given) -> int8 per output
// channel (symmetric), prepacked with its float bias.
c10::IValue pack(const torch::Tensor& weight, const torch::Tensor& bias, int64_t stride, int64_t padding,
                 const torch::Tensor& factor = {}) {
  return prepack(quantize_weight_per_channel(weight, factor), bias, stride, padding);
}

// A quantized kernel and its float bias (undefined: none).
struct Int8Kernel {
  torch::Tensor weight, bias;
};

c10::IValue prepack(const Int8Kernel& k, int64_t stride, int64_t padding) {
  return prepack(k.weight, k.bias, stride, padding);
}

// The kernel `name` of Int8Graph::kernels, taken out of `given` and checked against the layer's
// shape [Co,Ci,kh,kw] (and its bias, when it has one).
Int8Kernel take_given(std::map<std::string, torch::Tensor>& given, const std::string& name, std::vector<int64_t> shape,
                      bool has_bias) {
  const auto take = [&](const std::string& key) {
    const auto it = given.find(key);
    TORCH_CHECK(it != given.end(), "int8: no kernel '", key, "' for the network's layer '", name, "'");
    auto t = it->second;
    given.erase(it);
    return t.contiguous();
  };
  const auto weight = take(name + ".weight"), scales = take(name + ".scales");
  const auto bias = has_bias ? take(name + ".bias") : torch::Tensor();
  const int64_t co = shape[0];
  TORCH_CHECK(weight.scalar_type() == torch::kInt8 && weight.sizes() == at::IntArrayRef(shape), "int8: kernel '", name,
              ".weight' is ", weight.scalar_type(), " ", weight.sizes(), ", the layer's is Char ",
              at::IntArrayRef(shape));
  TORCH_CHECK(scales.scalar_type() == torch::kFloat64 && scales.dim() == 1 && scales.size(0) == co &&
                  (scales > 0).all().item<bool>() && torch::isfinite(scales).all().item<bool>(),
              "int8: kernel '", name, ".scales' must be ", co, " finite positive float64 values, got ",
              scales.scalar_type(), " ", scales.sizes());
  TORCH_CHECK(!bias.defined() || (bias.scalar_type() == torch::kFloat32 && bias.dim() == 1 && bias.size(0) == co &&
                                  torch::isfinite(bias).all().item<bool>()),
              "int8: kernel '", name, ".bias' must be ", co, " finite float32 values");
  // The file's bytes as they are, viewed as qint8 (_make_per_channel_quantized_tensor would copy them).
  auto qweight = at::_empty_per_channel_affine_quantized({0}, scales, torch::zeros({co}, torch::kLong), 0,
                                                         weight.options().dtype(torch::kQInt8));
  qweight.set_(weight.storage(), weight.storage_offset(), weight.sizes(), weight.strides());
  return {qweight, bias};
}

// A prepacked kernel back as Int8Graph::kernels's tensors under `name` (quantized::conv2d_unpack
// gives the int8 weight and the bias that were packed).
void unpack_into(std::map<std::string, torch::Tensor>& out, const std::string& name, const c10::IValue& packed) {
  torch::jit::Stack stack{packed};
  op("quantized::conv2d_unpack", "").callBoxed(&stack);
  const auto w = stack.at(0).toTensor();
  TORCH_CHECK(w.qscheme() == at::kPerChannelAffine && w.q_per_channel_axis() == 0 &&
                  (w.q_per_channel_zero_points() == 0).all().item<bool>(),
              "int8: kernel '", name, "' is not symmetric per output channel");
  out[name + ".weight"] = w.int_repr().contiguous();
  out[name + ".scales"] = w.q_per_channel_scales().to(torch::kFloat64).contiguous();
  if (!stack.at(1).isNone()) out[name + ".bias"] = stack.at(1).toTensor().to(torch::kFloat32).contiguous();
}

// Each submodule of `net` -> its name in the network's state ("encoder.layer1.0.conv1").
std::unordered_map<const torch::nn::Module*, std::string> module_names(const torch::nn::Module& net) {
  std::unordered_map<const torch::nn::Module*, std::string> names;
  for (const auto& m : net.named_modules("", /*include_self=*/false)) names[m.value().get()] = m.key();
  return names;
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

int64_t Int8EncoderDecoder::graph_points(const torch::Tensor& x) {
  torch::NoGradGuard no_grad;
  Count ops;
  encoder_decoder_graph(net_, ops, x);
  return static_cast<int64_t>(ops.i);
}

// (pose_graph runs the last convolution in float)
Int8PoseNet::Int8PoseNet(PoseNetImpl& net) : Int8Graph(net, {}, {}, {net.convs.back().get()}), net_(net) {}

int64_t Int8PoseNet::graph_points(const torch::Tensor& x) {
  torch::NoGradGuard no_grad;
  Count ops;
  pose_graph(net_, ops, x);
  return static_cast<int64_t>(ops.i);
}

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
  const auto names = module_names(st.net);
  const bool given = !st.given.empty();
  // Layer by layer, so that with release_float each float kernel goes as its int8 one comes (the
  // int8 kernels take the memory the float ones leave: the peak stays the float model's). Given
  // kernels (an int8 model file's) are all checked before any float kernel goes.
  const bool release_each = release_float && !given;
  for (auto* cb : st.int8_layers()) {
    TORCH_CHECK(cb->folded(), "int8: BatchNorm must be folded before quantizing");
    const auto& o = cb->conv->options;
    const int64_t stride = (*o.stride())[0], k = (*o.kernel_size())[0];
    const bool upconv = std::find(st.upconvs.begin(), st.upconvs.end(), cb) != st.upconvs.end();
    const auto& name = names.at(cb);
    if (given) {
      st.packed[cb] =
          prepack(take_given(st.given, name, {o.out_channels(), o.in_channels(), k, k}, true), stride, k / 2);
      if (upconv)
        st.packed_phases[cb] =
            prepack(take_given(st.given, name + ".phases", {4 * o.out_channels(), o.in_channels(), 2, 2}, true), 1, 1);
    } else {
      // The folded kernel quantized from the weight and BatchNorm's factor, not made in float.
      st.packed[cb] = pack(cb->conv->weight, cb->folded_bias(), stride, k / 2, cb->bn_scale());
      if (upconv)
        st.packed_phases[cb] = pack(phase_kernels(cb->folded_weight().to(torch::kFloat32)),
                                    cb->folded_bias().to(torch::kFloat32).repeat({4}), 1, 1);
    }
    if (release_each) cb->release_float_kernel();
  }
  for (auto* h : st.heads) {
    const auto& o = h->options;
    const int64_t stride = (*o.stride())[0], k = (*o.kernel_size())[0];
    st.packed[h] =
        given ? prepack(take_given(st.given, names.at(h), {o.out_channels(), o.in_channels(), k, k}, h->bias.defined()),
                        stride, k / 2)
              : pack(h->weight, h->bias, stride, k / 2);
    if (release_each) release_float_weight(h->weight);
  }
  if (given) {
    std::string left;
    for (const auto& kv : st.given) left += (left.empty() ? "" : ", ") + kv.first;
    TORCH_CHECK(left.empty(), "int8: kernels for no layer of the network: ", left);
    if (release_float) {
      for (auto* cb : st.int8_layers()) cb->release_float_kernel();
      for (auto* h : st.heads) release_float_weight(h->weight);
    }
  }
  st.released = release_float;
  st.quantized = true;
}

torch::Tensor Int8Graph::ranges() const {
  auto r = torch::empty({points(), 2}, torch::kFloat32);
  auto a = r.accessor<float, 2>();
  for (int64_t i = 0; i < points(); ++i) a[i][0] = state_->points[i].lo, a[i][1] = state_->points[i].hi;
  return r;
}

bool Int8Graph::float_released() const { return state_->released; }

std::map<std::string, torch::Tensor> Int8Graph::kernels() const {
  TORCH_CHECK(state_->quantized, "int8: the network is not quantized: it has no int8 kernels");
  const auto names = module_names(state_->net);
  std::map<std::string, torch::Tensor> out;
  for (const auto& [m, packed] : state_->packed) unpack_into(out, names.at(m), packed);
  for (const auto& [m, packed] : state_->packed_phases) unpack_into(out, names.at(m) + ".phases", packed);
  return out;
}

void Int8Graph::set_kernels(std::map<std::string, torch::Tensor> kernels) {
  TORCH_CHECK(!state_->quantized, "int8: kernels are set on a network not yet quantized");
  state_->given = std::move(kernels);
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
void quantize_with_ranges(Net& net, const torch::Tensor& ranges, const torch::Tensor& like, bool release_float,
                          const std::map<std::string, torch::Tensor>& kernels) {
  TORCH_CHECK(!net.is_training(), "int8: the network is in training mode (int8 is for inference)");
  auto int8 = std::make_shared<Int8Net>(net);
  // The ranges must be this network's, one per point: counted from the shapes of an input like the
  // network will see, before anything changes (a refused calibration leaves the float network).
  const int64_t points = int8->graph_points(like);
  TORCH_CHECK(ranges.dim() == 2 && ranges.size(0) == points, "int8: ", ranges.dim() == 2 ? ranges.size(0) : 0,
              " calibrated ranges for a network of ", points,
              " quantized points (a calibration of another network or geo version: calibrate again)");
  int8->set_ranges(ranges);
  int8->set_kernels(kernels);
  int8->quantize(release_float);
  // (oneDNN's int8 primitives are made at the first call, at the size it is given.)
  net.int8 = int8;
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
                   bool release_float, const std::map<std::string, torch::Tensor>& kernels) {
  quantize_with_ranges<Int8EncoderDecoder>(
      net, ranges, torch::zeros({1, net.encoder->options.in_channels, height, width}), release_float, kernels);
}

void quantize_int8(PoseNetImpl& net, const torch::Tensor& ranges, int64_t height, int64_t width, bool release_float,
                   const std::map<std::string, torch::Tensor>& kernels) {
  quantize_with_ranges<Int8PoseNet>(net, ranges, torch::zeros({1, 3 * net.options.seq_length, height, width}),
                                    release_float, kernels);
}

}  // namespace geo
