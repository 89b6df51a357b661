#include "models/int8_kernels.h"

#include <ATen/Parallel.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <cstdint>
#include <vector>

#include "models/fr.h"

namespace geo {

// FR's byte loops, compiled for AVX-512 and AVX2 besides the baseline (picked when the program
// loads, where function multi-versioning is available: GCC 12, Clang 14): vectorised over channels,
// 2-3x faster than SSE2 on 8-bit features.
#if defined(__x86_64__) && ((defined(__clang__) && __clang_major__ >= 14) || (!defined(__clang__) && __GNUC__ >= 12))
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
GEO_MULTIVERSIONED void requantize_into(const uint8_t* __restrict__ x, int64_t Ci, float factor, float offset,
                                        int64_t p0, int64_t p1, int64_t Co, uint8_t* __restrict__ y) {
  for (int64_t p = p0; p < p1; ++p) {
    const uint8_t* row = x + p * Ci;
    uint8_t* o = y + p * Co;
    each_channel(Ci, [&](int64_t c) { o[c] = rounded_byte(static_cast<float>(row[c]) * factor + offset); });
  }
}

// max |w_i c| over a row of n values, by the bits of |w_i c| as unsigned integers (for finite
// non-negative floats their order is the numbers' order: an integer maximum, which vectorises).
GEO_MULTIVERSIONED float row_abs_max(const float* __restrict__ w, int64_t n, float c) {
  uint32_t m = 0;
  for (int64_t i = 0; i < n; ++i) m = std::max(m, __builtin_bit_cast(uint32_t, w[i] * c) & 0x7fffffffu);
  return __builtin_bit_cast(float, m);
}

// ATen's per-channel quantization of the row w c: nearbyint((w_i c) x inverse) (to even, the
// product and the scaling each rounded to float32 as ATen's two multiplications are) clamped to int8.
GEO_MULTIVERSIONED void quantize_row(const float* __restrict__ w, int64_t n, float c, float inverse,
                                     int8_t* __restrict__ q) {
  for (int64_t i = 0; i < n; ++i) {
    const float product = w[i] * c;
    float v = std::nearbyint(product * inverse);
    v = v < -128.0f ? -128.0f : v;
    v = v > 127.0f ? 127.0f : v;
    q[i] = static_cast<int8_t>(static_cast<int32_t>(v));
  }
}

}  // namespace

torch::Tensor quantize_weight_per_channel(const torch::Tensor& weight, const torch::Tensor& channel_factor) {
  const auto w = weight.to(torch::kFloat32).contiguous();
  const int64_t Co = w.size(0), n = Co > 0 ? w.numel() / Co : 0;
  const auto factor =
      channel_factor.defined() ? channel_factor.to(torch::kFloat32).contiguous() : torch::ones({Co}, torch::kFloat32);
  TORCH_CHECK(factor.dim() == 1 && factor.size(0) == Co, "int8: a channel factor per output channel (", Co, "), got ",
              factor.sizes());
  const float* wp = w.data_ptr<float>();
  const float* fp = factor.data_ptr<float>();
  auto abs_max = torch::empty({Co}, torch::kFloat32);
  float* mp = abs_max.data_ptr<float>();
  const int64_t grain = std::max<int64_t>(1, 65536 / std::max<int64_t>(n, 1));
  at::parallel_for(0, Co, grain, [&](int64_t c0, int64_t c1) {
    for (int64_t c = c0; c < c1; ++c) mp[c] = row_abs_max(wp + c * n, n, fp[c]);
  });
  // The scales and their inverses as before, by LibTorch's own float operations.
  const auto scales = (abs_max / 127.0).clamp_min(1e-12).to(torch::kFloat64);
  const auto inverse = (1.0 / scales.to(torch::kFloat32)).contiguous();
  const float* ip = inverse.data_ptr<float>();
  auto q = torch::empty(w.sizes(), torch::kInt8);
  int8_t* qp = q.data_ptr<int8_t>();
  at::parallel_for(0, Co, grain, [&](int64_t c0, int64_t c1) {
    for (int64_t c = c0; c < c1; ++c) quantize_row(wp + c * n, n, fp[c], ip[c], qp + c * n);
  });
  return at::_make_per_channel_quantized_tensor(q, scales, torch::zeros({Co}, torch::kLong), 0);
}

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
  auto out =
      at::_empty_affine_quantized({B, Co, H, W}, parts[0].options(), scale, zero_point, at::MemoryFormat::ChannelsLast);
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
  for (int64_t b = 0; b < B; ++b)
    at::parallel_for(0, HW, 1024, [&](int64_t p0, int64_t p1) {
      quantize_planes(src + b * C * HW, C, HW, p0, p1, inv, zo, dst + b * C * HW);
    });
  return out;
}

torch::Tensor int8_feature_refinement(FeatureRefinementImpl& fr, const torch::Tensor& q_in, double out_scale,
                                      int64_t out_zp) {
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
  for (int64_t b = 0; b < B; ++b)
    at::parallel_for(b * HW, (b + 1) * HW, 256,
                     [&](int64_t p0, int64_t p1) { max_mean_over_channels(x, ac + b * C, p0, p1, C, z, s, sm, sa); });
  const auto& spatial = *fr.spatial;
  const int64_t k = spatial.options.kernel_size()->at(0);
  const auto w = spatial.weight.to(torch::kFloat32).contiguous();
  TORCH_CHECK(w.sizes() == torch::IntArrayRef({1, 2, k, k}) && !spatial.bias.defined(),
              "int8 FR: a spatial convolution of 2 -> 1 channels without bias expected, got ", w.sizes());
  auto conv = torch::empty({B, 1, H, W}, fopt);
  for (int64_t b = 0; b < B; ++b)
    at::parallel_for(0, H, 8, [&](int64_t y0, int64_t y1) {
      conv_two_planes(sm + b * HW, sa + b * HW, w.data_ptr<float>(), k, H, W, y0, y1, conv.data_ptr<float>() + b * HW);
    });
  const auto gate_s = fr.spatial_gate_from(conv).to(torch::kFloat32).contiguous();
  const float* as = gate_s.data_ptr<float>();

  auto out = at::_empty_affine_quantized({B, C, H, W}, q.options(), out_scale, out_zp, at::MemoryFormat::ChannelsLast);
  uint8_t* y = reinterpret_cast<uint8_t*>(out.data_ptr<c10::quint8>());
  std::vector<float> scaled(static_cast<size_t>(B * C));  // a_c s / out_scale
  for (int64_t i = 0; i < B * C; ++i) scaled[i] = ac[i] * s / static_cast<float>(out_scale);
  const float zo = static_cast<float>(out_zp) + 0.5f;
  for (int64_t b = 0; b < B; ++b)
    at::parallel_for(b * HW, (b + 1) * HW, 256,
                     [&](int64_t p0, int64_t p1) { gate_bytes(x, scaled.data() + b * C, as, p0, p1, C, z, zo, y); });
  return out;
}

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

}  // namespace geo
