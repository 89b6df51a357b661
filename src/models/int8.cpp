#include "models/int8.h"

#include <ATen/Parallel.h>
#include <ATen/core/dispatch/Dispatcher.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <unordered_map>
#include <utility>

#include "models/conv_bn.h"
#include "models/decoder.h"
#include "models/fr.h"
#include "models/layers.h"
#include "models/pose_net.h"
#include "models/resnet_encoder.h"
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

// FR's byte loops, compiled for AVX-512 and AVX2 besides the baseline (picked when the program
// loads, where GCC's function multi-versioning is available): vectorised over channels, 2-3x faster
// than SSE2 on 8-bit features.
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && __GNUC__ >= 12
#define GEO_MULTIVERSIONED __attribute__((target_clones("arch=x86-64-v4", "arch=x86-64-v3", "default")))
#else
#define GEO_MULTIVERSIONED
#endif

namespace {

// Channels in blocks of V: a loop of constant length, which the compiler turns into whole vector
// operations however few the channels (FR's counts are multiples of 16).
constexpr int64_t V = 16;

// f(c) for the channels 0..C-1: blocks of V, then the rest.
template <class F>
inline void each_channel(int64_t C, F&& f) {
  int64_t c = 0;
  for (; c + V <= C; c += V)
    for (int64_t l = 0; l < V; ++l) f(c + l);
  for (; c < C; ++c) f(c);
}

// v, a value on the byte scale plus 0.5, clamped to [0.5, 255.5] and truncated: rounded to the
// nearest of 0..255.
inline uint8_t rounded_byte(float v) {
  v = v < 0.5f ? 0.5f : v;
  v = v > 255.5f ? 255.5f : v;
  return static_cast<uint8_t>(static_cast<int32_t>(v));
}

// Max and sum over pixels [p0, p1) of each channel of x [pixels, C] (NHWC bytes).
GEO_MULTIVERSIONED void max_sum_over_pixels(const uint8_t* __restrict__ x, int64_t p0, int64_t p1, int64_t C,
                                            uint8_t* __restrict__ mx, int32_t* __restrict__ sum) {
  for (int64_t p = p0; p < p1; ++p) {
    const uint8_t* row = x + p * C;
    each_channel(C, [&](int64_t c) {
      mx[c] = row[c] > mx[c] ? row[c] : mx[c];
      sum[c] += row[c];
    });
  }
}

// Per pixel of [p0, p1): max and mean over the channels of s (x - z) a_c. V independent lanes, so
// that the compiler vectorises the reductions (it may not reorder one float accumulator).
GEO_MULTIVERSIONED void max_mean_over_channels(const uint8_t* __restrict__ x, const float* __restrict__ a, int64_t p0,
                                               int64_t p1, int64_t C, float z, float s, float* __restrict__ sm,
                                               float* __restrict__ sa) {
  constexpr int64_t L = V;
  for (int64_t p = p0; p < p1; ++p) {
    const uint8_t* row = x + p * C;
    float best[L], sum[L];
    for (int64_t l = 0; l < L; ++l) best[l] = -std::numeric_limits<float>::infinity(), sum[l] = 0.f;
    int64_t c = 0;
    for (; c + L <= C; c += L)
      for (int64_t l = 0; l < L; ++l) {
        const float v = (static_cast<float>(row[c + l]) - z) * a[c + l];
        best[l] = v > best[l] ? v : best[l];
        sum[l] += v;
      }
    for (; c < C; ++c) {
      const float v = (static_cast<float>(row[c]) - z) * a[c];
      best[0] = v > best[0] ? v : best[0];
      sum[0] += v;
    }
    for (int64_t l = 1; l < L; ++l) best[0] = best[l] > best[0] ? best[l] : best[0], sum[0] += sum[l];
    sm[p] = s * best[0];
    sa[p] = s * sum[0] / static_cast<float>(C);
  }
}

// y = round((x - z) a'_c g_p) + zero point, clamped to 0..255, for the pixels [p0, p1) (a' = a_c s /
// out_scale, zo = out_zero_point + 0.5).
GEO_MULTIVERSIONED void gate_bytes(const uint8_t* __restrict__ x, const float* __restrict__ a,
                                   const float* __restrict__ g, int64_t p0, int64_t p1, int64_t C, float z, float zo,
                                   uint8_t* __restrict__ y) {
  for (int64_t p = p0; p < p1; ++p) {
    const uint8_t* row = x + p * C;
    uint8_t* o = y + p * C;
    const float gp = g[p];
    each_channel(C, [&](int64_t c) { o[c] = rounded_byte((static_cast<float>(row[c]) - z) * a[c] * gp + zo); });
  }
}

// Rows [y0, y1) of the k x k convolution (zero padding k/2, no bias) of two [H,W] planes with w
// [2,k,k] into out [H,W]: FR's spatial gate (its 5 M multiply-adds at 128x416 take oneDNN ~1 ms,
// set up for wide channel counts; this loop vectorises over the row).
GEO_MULTIVERSIONED void conv_two_planes(const float* __restrict__ in0, const float* __restrict__ in1,
                                        const float* __restrict__ w, int64_t k, int64_t H, int64_t W, int64_t y0,
                                        int64_t y1, float* __restrict__ out) {
  const int64_t pad = k / 2;
  for (int64_t y = y0; y < y1; ++y) {
    float* acc = out + y * W;
    for (int64_t x = 0; x < W; ++x) acc[x] = 0.f;
    for (int64_t c = 0; c < 2; ++c)
      for (int64_t ky = 0; ky < k; ++ky) {
        const int64_t iy = y + ky - pad;
        if (iy < 0 || iy >= H) continue;
        const float* src = (c == 0 ? in0 : in1) + iy * W;
        for (int64_t kx = 0; kx < k; ++kx) {
          const float wv = w[(c * k + ky) * k + kx];
          const int64_t lo = std::max<int64_t>(0, pad - kx), hi = std::min<int64_t>(W, W + pad - kx);
          const float* s = src + kx - pad;
          for (int64_t x = lo; x < hi; ++x) acc[x] += wv * s[x];
        }
      }
  }
}

// Pixels [p0, p1) of x [C, HW] (float planes) quantized into y [HW, C] (NHWC bytes): round(x / scale)
// + zero_point clamped to 0..255, computed over a block of pixels per channel (vectorised), then
// stored interleaved.
GEO_MULTIVERSIONED void quantize_planes(const float* __restrict__ x, int64_t C, int64_t HW, int64_t p0, int64_t p1,
                                        float inv_scale, float zo, uint8_t* __restrict__ y) {
  constexpr int64_t N = 64;
  uint8_t block[N];
  for (int64_t p = p0; p < p1; p += N) {
    const int64_t n = std::min(N, p1 - p);
    for (int64_t c = 0; c < C; ++c) {
      const float* src = x + c * HW + p;
      for (int64_t i = 0; i < n; ++i) block[i] = rounded_byte(src[i] * inv_scale + zo);  // zo = zero_point + 0.5
      for (int64_t i = 0; i < n; ++i) y[(p + i) * C + c] = block[i];
    }
  }
}

// Pixels [p0, p1) of x [pixels, Ci] (bytes) into Ci channels of y [pixels, Co]: round(x factor +
// offset) clamped to 0..255 (offset = the output's zero point - x's zero point x factor + 0.5).
GEO_MULTIVERSIONED void requantize_into(const uint8_t* __restrict__ x, int64_t Ci, float factor, float offset, int64_t p0,
                                        int64_t p1, int64_t Co, uint8_t* __restrict__ y) {
  for (int64_t p = p0; p < p1; ++p) {
    const uint8_t* row = x + p * Ci;
    uint8_t* o = y + p * Co;
    each_channel(Ci, [&](int64_t c) { o[c] = rounded_byte(static_cast<float>(row[c]) * factor + offset); });
  }
}

}  // namespace

torch::Tensor cat_int8(const std::vector<torch::Tensor>& parts_in, double scale, int64_t zero_point) {
  TORCH_CHECK(!parts_in.empty(), "int8: nothing to concatenate");
  std::vector<torch::Tensor> parts;
  int64_t Co = 0;
  for (const auto& t : parts_in) {
    TORCH_CHECK(t.dim() == 4 && t.scalar_type() == torch::kQUInt8 && t.size(0) == parts_in[0].size(0) &&
                    t.size(2) == parts_in[0].size(2) && t.size(3) == parts_in[0].size(3),
                "int8: concatenating quint8 [B,C,H,W] tensors of one size, got ", t.sizes(), " beside ",
                parts_in[0].sizes());
    parts.push_back(t.contiguous(at::MemoryFormat::ChannelsLast));
    Co += t.size(1);
  }
  const int64_t B = parts[0].size(0), H = parts[0].size(2), W = parts[0].size(3);
  auto out = at::_empty_affine_quantized({B, Co, H, W}, parts[0].options(), scale, zero_point,
                                         at::MemoryFormat::ChannelsLast);
  uint8_t* y = reinterpret_cast<uint8_t*>(out.data_ptr<c10::quint8>());
  at::parallel_for(0, B * H * W, 256, [&](int64_t p0, int64_t p1) {
    int64_t offset = 0;
    for (const auto& t : parts) {
      const float factor = static_cast<float>(t.q_scale() / scale);
      const float shift = static_cast<float>(zero_point) - static_cast<float>(t.q_zero_point()) * factor + 0.5f;
      requantize_into(reinterpret_cast<const uint8_t*>(t.data_ptr<c10::quint8>()), t.size(1), factor, shift, p0, p1, Co,
                      y + offset);
      offset += t.size(1);
    }
  });
  return out;
}

// x float [B,C,H,W] -> quint8 [B,C,H,W] channels-last with (scale, zero_point), as
// at::quantize_per_tensor computes it (ties rounded up rather than to even) at ~10x its speed here
// (it took ~2 ms for the PoseNet's 9-channel input at 128x416).
torch::Tensor quantize_to_nhwc(const torch::Tensor& x_in, double scale, int64_t zero_point) {
  const auto x = x_in.to(torch::kFloat32).contiguous();
  TORCH_CHECK(x.dim() == 4, "int8: quantizing a [B,C,H,W] tensor, got ", x.sizes());
  const int64_t B = x.size(0), C = x.size(1), HW = x.size(2) * x.size(3);
  auto out = at::_empty_affine_quantized(x.sizes(), x.options().dtype(torch::kQUInt8), scale, zero_point,
                                         at::MemoryFormat::ChannelsLast);
  const float* src = x.data_ptr<float>();
  uint8_t* dst = reinterpret_cast<uint8_t*>(out.data_ptr<c10::quint8>());
  const float inv = static_cast<float>(1.0 / scale), zo = static_cast<float>(zero_point) + 0.5f;
  for (int64_t b = 0; b < B; ++b) at::parallel_for(0, HW, 1024, [&](int64_t p0, int64_t p1) {
    quantize_planes(src + b * C * HW, C, HW, p0, p1, inv, zo, dst + b * C * HW);
  });
  return out;
}

torch::Tensor int8_feature_refinement(FeatureRefinementImpl& fr, const torch::Tensor& q_in, double out_scale, int64_t out_zp) {
  const auto q = q_in.contiguous(at::MemoryFormat::ChannelsLast);
  const int64_t B = q.size(0), C = q.size(1), H = q.size(2), W = q.size(3), HW = H * W;
  const float s = static_cast<float>(q.q_scale()), z = static_cast<float>(q.q_zero_point());
  const uint8_t* x = reinterpret_cast<const uint8_t*>(q.data_ptr<c10::quint8>());
  auto fopt = torch::TensorOptions().dtype(torch::kFloat32);

  // Max and sum over space per channel: pixel ranges in parallel, each with its own partial results
  // (C is often too small to split), merged after.
  auto cmax = torch::empty({B, C, 1, 1}, fopt), cmean = torch::empty({B, C, 1, 1}, fopt);
  float *cm = cmax.data_ptr<float>(), *ca = cmean.data_ptr<float>();
  const int64_t parts = std::max<int64_t>(1, std::min<int64_t>(at::get_num_threads(), HW / 64));
  for (int64_t b = 0; b < B; ++b) {
    std::vector<uint8_t> part_max(parts * C, 0);
    std::vector<int32_t> part_sum(parts * C, 0);  // 255 x pixels: fits up to 8 M pixels
    at::parallel_for(0, parts, 1, [&](int64_t k0, int64_t k1) {
      for (int64_t k = k0; k < k1; ++k)
        max_sum_over_pixels(x + b * HW * C, HW * k / parts, HW * (k + 1) / parts, C, part_max.data() + k * C,
                            part_sum.data() + k * C);
    });
    for (int64_t c = 0; c < C; ++c) {
      uint8_t m = 0;
      int64_t total = 0;
      for (int64_t k = 0; k < parts; ++k) {
        m = std::max(m, part_max[k * C + c]);
        total += part_sum[k * C + c];
      }
      cm[b * C + c] = s * (static_cast<float>(m) - z);
      ca[b * C + c] = s * (static_cast<float>(static_cast<double>(total) / static_cast<double>(HW)) - z);
    }
  }
  const auto gate_c = fr.channel_gate_of(cmax, cmean).to(torch::kFloat32).contiguous();
  const float* ac = gate_c.data_ptr<float>();

  // Max and mean over the channels of x * a_c per pixel, then the spatial gate's convolution.
  auto smax = torch::empty({B, 1, H, W}, fopt), smean = torch::empty({B, 1, H, W}, fopt);
  float *sm = smax.data_ptr<float>(), *sa = smean.data_ptr<float>();
  for (int64_t b = 0; b < B; ++b) at::parallel_for(b * HW, (b + 1) * HW, 256, [&](int64_t p0, int64_t p1) {
    max_mean_over_channels(x, ac + b * C, p0, p1, C, z, s, sm, sa);
  });
  const auto& spatial = *fr.spatial;
  const int64_t k = spatial.options.kernel_size()->at(0);
  const auto w = spatial.weight.to(torch::kFloat32).contiguous();
  TORCH_CHECK(w.sizes() == torch::IntArrayRef({1, 2, k, k}) && !spatial.bias.defined(),
              "int8 FR: a spatial convolution of 2 -> 1 channels without bias expected, got ", w.sizes());
  auto conv = torch::empty({B, 1, H, W}, fopt);
  for (int64_t b = 0; b < B; ++b) at::parallel_for(0, H, 8, [&](int64_t y0, int64_t y1) {
    conv_two_planes(sm + b * HW, sa + b * HW, w.data_ptr<float>(), k, H, W, y0, y1, conv.data_ptr<float>() + b * HW);
  });
  const auto gate_s = fr.spatial_gate_from(conv).to(torch::kFloat32).contiguous();
  const float* as = gate_s.data_ptr<float>();

  auto out = at::_empty_affine_quantized({B, C, H, W}, q.options(), out_scale, out_zp, at::MemoryFormat::ChannelsLast);
  uint8_t* y = reinterpret_cast<uint8_t*>(out.data_ptr<c10::quint8>());
  std::vector<float> scaled(static_cast<size_t>(B * C));  // a_c s / out_scale
  for (int64_t i = 0; i < B * C; ++i) scaled[i] = ac[i] * s / static_cast<float>(out_scale);
  const float zo = static_cast<float>(out_zp) + 0.5f;
  for (int64_t b = 0; b < B; ++b) at::parallel_for(b * HW, (b + 1) * HW, 256, [&](int64_t p0, int64_t p1) {
    gate_bytes(x, scaled.data() + b * C, as, p0, p1, C, z, zo, y);
  });
  return out;
}

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

  State(torch::nn::Module& n, std::vector<Conv2dImpl*> h, std::vector<ConvBnImpl*> u)
      : net(n), heads(std::move(h)), upconvs(std::move(u)) {}
  torch::nn::Module& net;
  std::vector<Conv2dImpl*> heads;
  std::vector<ConvBnImpl*> upconvs;
  std::vector<Point> points;
  bool quantized = false;
  std::unordered_map<const torch::nn::Module*, c10::IValue> packed;
  std::unordered_map<const torch::nn::Module*, c10::IValue> packed_phases;  // the upconvs' 2x2 phase kernels
  std::optional<c10::OperatorHandle> conv, conv_relu, add_relu;
};

namespace {

// phases [B,4*Co,h+1,w+1] quint8 NHWC (phase (a, b) of output pixel (2i+a, 2j+b) in channels
// (2a+b)*Co.. of pixel (i+a, j+b)) -> [B,Co,2h,2w] quint8 NHWC, the same scale and zero point.
torch::Tensor interleave_phases_int8(const torch::Tensor& phases_in, int64_t Co) {
  const auto ph = phases_in.contiguous(at::MemoryFormat::ChannelsLast);
  const int64_t B = ph.size(0), h = ph.size(2) - 1, w = ph.size(3) - 1;
  TORCH_CHECK(ph.size(1) == 4 * Co, "int8: phases of ", ph.size(1), " channels for ", Co, " outputs");
  auto out = at::_empty_affine_quantized({B, Co, 2 * h, 2 * w}, ph.options(), ph.q_scale(), ph.q_zero_point(),
                                         at::MemoryFormat::ChannelsLast);
  const uint8_t* src = reinterpret_cast<const uint8_t*>(ph.data_ptr<c10::quint8>());
  uint8_t* dst = reinterpret_cast<uint8_t*>(out.data_ptr<c10::quint8>());
  at::parallel_for(0, B * 2 * h, 8, [&](int64_t r0, int64_t r1) {
    for (int64_t r = r0; r < r1; ++r) {
      const int64_t b = r / (2 * h), y = r % (2 * h), i = y / 2, a = y % 2;
      for (int64_t x = 0; x < 2 * w; ++x) {
        const int64_t j = x / 2, c = x % 2;
        std::memcpy(dst + ((b * 2 * h + y) * 2 * w + x) * Co,
                    src + ((b * (h + 1) + i + a) * (w + 1) + j + c) * 4 * Co + (2 * a + c) * Co, Co);
      }
    }
  });
  return out;
}

// A network's graph, once, for both passes: `Ops` computes each step in float while recording the
// ranges of its quantized points (Observe) or in int8 (Quantized). Every point takes the next slot,
// in this order: statements, never two slots in one expression (C++ leaves their order open).
template <class Ops>
std::vector<torch::Tensor> encoder_decoder_graph(EncoderDecoderImpl& net, Ops& ops, const torch::Tensor& x) {
  auto& enc = *net.encoder;
  std::vector<torch::Tensor> feats;
  const auto input = ops.quantize(x);
  feats.push_back(ops.conv(*enc.conv1, input));
  // (Max-pooling keeps a quantized tensor's scale: no point of its own, the same call for both.)
  feats.push_back(torch::max_pool2d(feats.back(), {3, 3}, {2, 2}, {1, 1}, {1, 1}));
  for (size_t s = 0; s < enc.stages.size(); ++s) {
    auto y = feats.back();
    for (const auto& m : enc.stages[s]->children()) {
      if (auto* b = m->as<BottleneckImpl>()) {
        auto r = ops.conv(*b->c1, y);
        r = ops.conv(*b->c2, r);
        r = ops.conv(*b->c3, r);
        const auto shortcut = ops.conv(*b->proj, y);
        y = ops.add_relu(r, shortcut);
      } else if (auto* bb = m->as<BasicBlockImpl>()) {
        auto r = ops.conv(*bb->c1, y);
        r = ops.conv(*bb->c2, r);
        const auto shortcut = bb->proj ? ops.conv(*bb->proj, y) : y;
        y = ops.add_relu(r, shortcut);
      } else {
        TORCH_CHECK(false, "int8: unknown block in the encoder");
      }
    }
    if (!enc.refine.empty()) y = ops.fr(*enc.refine[s], y);
    feats.push_back(y);
  }
  const auto mode = net.options.upsample;
  std::vector<torch::Tensor> preds;  // coarsest first while building
  auto y = feats[5];
  for (int k = 0; k < 6; ++k) {
    const torch::Tensor& ref = k < 5 ? feats[4 - k] : x;
    std::vector<torch::Tensor> parts;
    parts.reserve(3);
    parts.push_back(resize_like(ops.upconv(*net.upconv[k], y, mode), ref));
    if (k < 5) parts.push_back(feats[4 - k]);
    if (k >= 3) parts.push_back(ops.quantize(resize_like(upsample2(preds.back(), mode), ref)));
    y = ops.cat(parts);
    y = ops.conv(*net.iconv[k], y);
    if (!net.refine.empty()) y = ops.fr(*net.refine[k], y);
    if (k >= 2) preds.push_back(net.head(ops.pred(*net.pred[k - 2], y)));
  }
  return {preds[3], preds[2], preds[1], preds[0]};
}

template <class Ops>
std::vector<torch::Tensor> pose_graph(PoseNetImpl& net, Ops& ops, const torch::Tensor& x) {
  // The last convolution stays in float (1% of the multiply-adds: 256 channels on a few pixels):
  // 8 bits at its output, which the heads average, moved the learning check's ATE by +8% (float: -2%).
  auto y = ops.quantize(x);
  for (size_t i = 0; i + 1 < net.convs.size(); ++i) y = ops.conv(*net.convs[i], y);
  return {net.convs.back()->forward(ops.dequantize(y))};
}

struct Observe {
  std::vector<Int8Graph::State::Point>& points;
  size_t i = 0;
  torch::Tensor seen(torch::Tensor t) {
    if (i == points.size()) points.emplace_back();
    points[i++].see(t);
    return t;
  }
  torch::Tensor quantize(const torch::Tensor& x) { return seen(x); }
  torch::Tensor conv(ConvBnImpl& m, const torch::Tensor& x) { return seen(m.forward(x)); }
  torch::Tensor upconv(ConvBnImpl& m, const torch::Tensor& x, UpsampleMode mode) {
    return seen(mode == UpsampleMode::kNearest ? m.forward_upsampled(x) : m.forward(upsample2(x, mode)));
  }
  torch::Tensor add_relu(const torch::Tensor& a, const torch::Tensor& b) { return seen(torch::relu(a + b)); }
  torch::Tensor fr(FeatureRefinementImpl& m, const torch::Tensor& x) { return seen(m.forward(x)); }
  torch::Tensor cat(const std::vector<torch::Tensor>& parts) { return seen(torch::cat(parts, 1)); }
  torch::Tensor pred(Conv2dImpl& m, const torch::Tensor& y) { return seen(m.forward(y)); }
  torch::Tensor dequantize(const torch::Tensor& y) { return y; }
};

struct Quantized {
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

// w [Co,Ci,k,k] float -> int8 per output channel (symmetric), prepacked with its float bias.
c10::IValue pack(const torch::Tensor& weight, const torch::Tensor& bias, int64_t stride, int64_t padding) {
  const auto w = weight.to(torch::kFloat32).contiguous();
  const auto scales = (w.abs().amax({1, 2, 3}) / 127.0).clamp_min(1e-12).to(torch::kFloat64);
  const auto qw = at::quantize_per_channel(w, scales, torch::zeros({w.size(0)}, torch::kLong), 0, torch::kQInt8);
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

Int8Graph::Int8Graph(torch::nn::Module& net, std::vector<Conv2dImpl*> heads, std::vector<ConvBnImpl*> upconvs)
    : state_(std::make_unique<State>(net, std::move(heads), std::move(upconvs))) {}
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

Int8PoseNet::Int8PoseNet(PoseNetImpl& net) : Int8Graph(net, {}, {}), net_(net) {}

torch::Tensor Int8PoseNet::forward(const torch::Tensor& x) {
  return run(x, [this](auto& ops, const torch::Tensor& in) { return pose_graph(net_, ops, in); }).at(0);
}

void Int8Graph::quantize() {
  auto& st = *state_;
  TORCH_CHECK(!st.points.empty(), "int8: nothing was observed: run the network on calibration inputs first");
  TORCH_CHECK(!select_int8_engine().empty(), "int8: this LibTorch has no quantized engine");
  for (auto& p : st.points) p.fix();
  st.conv = op("quantized::conv2d", "new");
  st.conv_relu = op("quantized::conv2d_relu", "new");
  st.add_relu = op("quantized::add_relu", "");
  for (const auto& m : st.net.modules(/*include_self=*/false)) {
    if (auto* cb = m->as<ConvBnImpl>()) {
      TORCH_CHECK(cb->folded(), "int8: BatchNorm must be folded before quantizing");
      const auto& o = cb->conv->options;
      st.packed[cb] = pack(cb->folded_weight(), cb->folded_bias(), (*o.stride())[0], (*o.kernel_size())[0] / 2);
    }
  }
  for (auto* h : st.heads) {
    const auto& o = h->options;
    st.packed[h] = pack(h->weight, h->bias, (*o.stride())[0], (*o.kernel_size())[0] / 2);
  }
  for (auto* u : st.upconvs)
    st.packed_phases[u] = pack(phase_kernels(u->folded_weight().to(torch::kFloat32)),
                               u->folded_bias().to(torch::kFloat32).repeat({4}), 1, 1);
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
void quantize_with_ranges(Net& net, const torch::Tensor& ranges, const torch::Tensor& probe) {
  auto int8 = std::make_shared<Int8Net>(net);
  int8->set_ranges(ranges);
  int8->quantize();
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
void quantize_observed(Net& net) {
  TORCH_CHECK(net.int8, "int8: the network was not observed (observe_int8) before quantize_int8");
  net.int8->quantize();
}

}  // namespace

void observe_int8(EncoderDecoderImpl& net) { net.int8 = std::make_shared<Int8EncoderDecoder>(net); }
void observe_int8(PoseNetImpl& net) { net.int8 = std::make_shared<Int8PoseNet>(net); }
void quantize_int8(EncoderDecoderImpl& net) { quantize_observed(net); }
void quantize_int8(PoseNetImpl& net) { quantize_observed(net); }

void quantize_int8(EncoderDecoderImpl& net, const torch::Tensor& ranges, int64_t height, int64_t width) {
  quantize_with_ranges<Int8EncoderDecoder>(net, ranges, torch::zeros({1, net.encoder->options.in_channels, height, width}));
}

void quantize_int8(PoseNetImpl& net, const torch::Tensor& ranges, int64_t height, int64_t width) {
  quantize_with_ranges<Int8PoseNet>(net, ranges, torch::zeros({1, 3 * net.options.seq_length, height, width}));
}

}  // namespace geo
