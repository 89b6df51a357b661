#include "losses/photometric.h"

#include <ATen/Dispatch.h>
#include <ATen/Parallel.h>
#include <torch/autograd.h>

#include <algorithm>
#include <cmath>

#include "core/tensor_checks.h"

namespace geo {

namespace {
torch::Tensor mean3x3(const torch::Tensor& x) {
  namespace F = torch::nn::functional;
  return F::avg_pool2d(x, F::AvgPool2dFuncOptions(3).stride(1).padding(1).count_include_pad(false));
}
}  // namespace

torch::Tensor ssim(const torch::Tensor& x, const torch::Tensor& y) {
  TORCH_CHECK(x.dim() == 4, "x must be [B,C,H,W], got ", x.sizes());
  TORCH_CHECK(x.sizes() == y.sizes(), "x ", x.sizes(), " and y ", y.sizes(), " must match");
  constexpr double C1 = 0.01 * 0.01;  // SSIM constants for [0,1] intensities (Wang et al., GeoNet)
  constexpr double C2 = 0.03 * 0.03;
  const auto mu_x = mean3x3(x), mu_y = mean3x3(y);
  const auto sigma_x = mean3x3(x * x) - mu_x * mu_x;
  const auto sigma_y = mean3x3(y * y) - mu_y * mu_y;
  const auto sigma_xy = mean3x3(x * y) - mu_x * mu_y;
  const auto n = (2 * mu_x * mu_y + C1) * (2 * sigma_xy + C2);
  const auto d = (mu_x * mu_x + mu_y * mu_y + C1) * (sigma_x + sigma_y + C2);
  return n / d;
}

torch::Tensor photometric_error_channels_reference(const torch::Tensor& x, const torch::Tensor& y, double alpha) {
  TORCH_CHECK(alpha >= 0 && alpha <= 1, "alpha must be in [0,1], got ", alpha);
  const auto dssim = ((1 - ssim(x, y)) / 2).clamp(0, 1);
  return alpha * dssim + (1 - alpha) * (x - y).abs();
}

namespace {

// The CPU kernel of photometric_error_channels: one pass per image plane instead of ~25 tensor
// operations (five 3x3 mean pools, products, the SSIM fraction, clamp, L1), each a trip through
// memory; its backward is written out below rather than recorded op by op.
constexpr double kC1 = 0.01 * 0.01, kC2 = 0.03 * 0.03;

// out = 3x3 box sum of `in` with zero padding (out may be in); tmp holds H*W values.
template <typename T>
void box3(const T* in, T* out, T* tmp, int64_t H, int64_t W) {
  for (int64_t i = 0; i < H; ++i) {
    const T* r = in + i * W;
    T* t = tmp + i * W;
    for (int64_t j = 0; j < W; ++j) t[j] = r[j] + (j > 0 ? r[j - 1] : T(0)) + (j + 1 < W ? r[j + 1] : T(0));
  }
  for (int64_t i = 0; i < H; ++i) {
    const T* t = tmp + i * W;
    T* o = out + i * W;
    for (int64_t j = 0; j < W; ++j) o[j] = t[j] + (i > 0 ? t[j - W] : T(0)) + (i + 1 < H ? t[j + W] : T(0));
  }
}

// buf[0..4] <- 3x3 box sums of x, y, x², y², xy (buf holds 6 planes; the last is scratch).
template <typename T>
void box_moments(const T* x, const T* y, T* buf, int64_t H, int64_t W) {
  const int64_t n = H * W;
  T *sx = buf, *sy = buf + n, *sxx = buf + 2 * n, *syy = buf + 3 * n, *sxy = buf + 4 * n, *tmp = buf + 5 * n;
  for (int64_t k = 0; k < n; ++k) {
    sxx[k] = x[k] * x[k];
    syy[k] = y[k] * y[k];
    sxy[k] = x[k] * y[k];
  }
  box3(x, sx, tmp, H, W);
  box3(y, sy, tmp, H, W);
  for (T* p : {sxx, syy, sxy}) box3(p, p, tmp, H, W);
}

// 1 / (number of window pixels inside the image) at (i, j): TensorFlow's 'SAME' average pooling.
template <typename T>
T inv_count(int64_t i, int64_t j, int64_t H, int64_t W) {
  const int64_t rows = 1 + (i > 0) + (i + 1 < H), cols = 1 + (j > 0) + (j + 1 < W);
  return T(1) / static_cast<T>(rows * cols);
}

template <typename T>
struct SsimTerms {
  T A, B, C, D, S;
  SsimTerms(T m1, T m2, T m11, T m22, T m12)
      : A(2 * m1 * m2 + T(kC1)), B(2 * (m12 - m1 * m2) + T(kC2)), C(m1 * m1 + m2 * m2 + T(kC1)),
        D((m11 - m1 * m1) + (m22 - m2 * m2) + T(kC2)), S(A * B / (C * D)) {}
};

template <typename T>
void photometric_forward_plane(const T* x, const T* y, T* out, T* buf, int64_t H, int64_t W, T alpha) {
  const int64_t n = H * W;
  box_moments(x, y, buf, H, W);
  for (int64_t i = 0; i < H; ++i)
    for (int64_t j = 0; j < W; ++j) {
      const int64_t k = i * W + j;
      const T inv = inv_count<T>(i, j, H, W);
      const SsimTerms<T> t(buf[k] * inv, buf[n + k] * inv, buf[2 * n + k] * inv, buf[3 * n + k] * inv,
                           buf[4 * n + k] * inv);
      const T dssim = std::min(std::max((1 - t.S) / 2, T(0)), T(1));
      out[k] = alpha * dssim + (1 - alpha) * std::abs(x[k] - y[k]);
    }
}

template <typename T>
void photometric_backward_plane(const T* x, const T* y, const T* g, T* gx, T* gy, T* buf, int64_t H, int64_t W,
                                T alpha) {
  const int64_t n = H * W;
  box_moments(x, y, buf, H, W);
  // Per window centre p: w = dLoss/dS / count, times dS/d(mean x, mean y, mean x², mean xy);
  // written over the moments (each pixel reads its own five values first).
  T *p1 = buf, *p2 = buf + n, *p11 = buf + 2 * n, *p12 = buf + 3 * n, *tmp = buf + 5 * n;
  for (int64_t i = 0; i < H; ++i)
    for (int64_t j = 0; j < W; ++j) {
      const int64_t k = i * W + j;
      const T inv = inv_count<T>(i, j, H, W);
      const T m1 = buf[k] * inv, m2 = buf[n + k] * inv;
      const SsimTerms<T> t(m1, m2, buf[2 * n + k] * inv, buf[3 * n + k] * inv, buf[4 * n + k] * inv);
      const T dssim = (1 - t.S) / 2;
      // clamp(dssim, 0, 1) passes the gradient where 0 <= dssim <= 1 (as torch's clamp).
      const T w = (dssim >= 0 && dssim <= 1) ? g[k] * (-alpha / 2) * inv : T(0);
      const T CD = t.C * t.D;
      const T dA = t.B / CD, dB = t.A / CD, dC = -t.S / t.C, dD = -t.S / t.D;
      p1[k] = w * (2 * m2 * (dA - dB) + 2 * m1 * (dC - dD));
      p2[k] = w * (2 * m1 * (dA - dB) + 2 * m2 * (dC - dD));
      p11[k] = w * dD;  // d/d(mean x²) = d/d(mean y²)
      p12[k] = w * 2 * dB;
    }
  for (T* p : {p1, p2, p11, p12}) box3(p, p, tmp, H, W);  // the box is its own adjoint
  for (int64_t k = 0; k < n; ++k) {
    const T d = x[k] - y[k];
    const T l1 = (1 - alpha) * g[k] * static_cast<T>((d > 0) - (d < 0));
    if (gx) gx[k] = p1[k] + 2 * x[k] * p11[k] + y[k] * p12[k] + l1;
    if (gy) gy[k] = p2[k] + 2 * y[k] * p11[k] + x[k] * p12[k] - l1;
  }
}

struct FusedPhotometric : torch::autograd::Function<FusedPhotometric> {
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& x_in,
                               const torch::Tensor& y_in, double alpha) {
    const auto x = x_in.contiguous(), y = y_in.contiguous();
    ctx->save_for_backward({x, y});
    ctx->saved_data["alpha"] = alpha;
    auto out = torch::empty_like(x);
    const int64_t H = x.size(2), W = x.size(3), planes = x.size(0) * x.size(1);
    AT_DISPATCH_FLOATING_TYPES(x.scalar_type(), "photometric_forward", [&] {
      const scalar_t *xp = x.data_ptr<scalar_t>(), *yp = y.data_ptr<scalar_t>();
      scalar_t* op = out.data_ptr<scalar_t>();
      at::parallel_for(0, planes, 1, [&](int64_t begin, int64_t end) {
        std::vector<scalar_t> buf(6 * H * W);
        for (int64_t p = begin; p < end; ++p)
          photometric_forward_plane(xp + p * H * W, yp + p * H * W, op + p * H * W, buf.data(), H, W,
                                    static_cast<scalar_t>(alpha));
      });
    });
    return out;
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto saved = ctx->get_saved_variables();
    const auto &x = saved[0], &y = saved[1];
    const double alpha = ctx->saved_data["alpha"].toDouble();
    const auto g = grads[0].contiguous();
    const bool need_x = ctx->needs_input_grad(0), need_y = ctx->needs_input_grad(1);
    torch::Tensor gx = need_x ? torch::empty_like(x) : torch::Tensor();
    torch::Tensor gy = need_y ? torch::empty_like(y) : torch::Tensor();
    const int64_t H = x.size(2), W = x.size(3), planes = x.size(0) * x.size(1), n = H * W;
    AT_DISPATCH_FLOATING_TYPES(x.scalar_type(), "photometric_backward", [&] {
      const scalar_t *xp = x.data_ptr<scalar_t>(), *yp = y.data_ptr<scalar_t>(), *gp = g.data_ptr<scalar_t>();
      scalar_t* gxp = need_x ? gx.data_ptr<scalar_t>() : nullptr;
      scalar_t* gyp = need_y ? gy.data_ptr<scalar_t>() : nullptr;
      at::parallel_for(0, planes, 1, [&](int64_t begin, int64_t end) {
        std::vector<scalar_t> buf(6 * n);
        for (int64_t p = begin; p < end; ++p)
          photometric_backward_plane(xp + p * n, yp + p * n, gp + p * n, gxp ? gxp + p * n : nullptr,
                                     gyp ? gyp + p * n : nullptr, buf.data(), H, W, static_cast<scalar_t>(alpha));
      });
    });
    return {gx, gy, torch::Tensor()};
  }
};

}  // namespace

torch::Tensor photometric_error_channels(const torch::Tensor& x, const torch::Tensor& y, double alpha) {
  TORCH_CHECK(alpha >= 0 && alpha <= 1, "alpha must be in [0,1], got ", alpha);
  TORCH_CHECK(x.dim() == 4, "x must be [B,C,H,W], got ", x.sizes());
  TORCH_CHECK(x.sizes() == y.sizes(), "x ", x.sizes(), " and y ", y.sizes(), " must match");
  const bool fused = fused_cpu_kernel_applies(x) && fused_cpu_kernel_applies(y) && x.scalar_type() == y.scalar_type();
  return fused ? FusedPhotometric::apply(x, y, alpha) : photometric_error_channels_reference(x, y, alpha);
}

torch::Tensor photometric_error(const torch::Tensor& x, const torch::Tensor& y, double alpha) {
  return photometric_error_channels(x, y, alpha).mean(1, /*keepdim=*/true);
}

torch::Tensor channel_l2_norm(const torch::Tensor& x) {
  TORCH_CHECK(x.dim() == 4, "x must be [B,C,H,W], got ", x.sizes());
  const auto squares = x.square().sum(1, /*keepdim=*/true);
  if (!torch::GradMode::is_enabled() || !x.requires_grad()) return squares.sqrt_();
  // sqrt's gradient is infinite at 0: the zero branch takes those pixels (their gradient is 0).
  return torch::where(squares > 0, squares.clamp_min(1e-30).sqrt(), torch::zeros_like(squares));
}

std::vector<torch::Tensor> image_pyramid(const torch::Tensor& image, int num_scales) {
  TORCH_CHECK(image.dim() == 4, "image must be [B,C,H,W], got ", image.sizes());
  const int64_t f = int64_t{1} << (num_scales - 1);
  TORCH_CHECK(image.size(2) % f == 0 && image.size(3) % f == 0, "image ", image.sizes(),
              ": height and width must be divisible by ", f, " for ", num_scales, " scales");
  std::vector<torch::Tensor> out{image};
  for (int s = 1; s < num_scales; ++s)
    out.push_back(torch::nn::functional::avg_pool2d(out.back(), torch::nn::functional::AvgPool2dFuncOptions(2)));
  return out;
}

torch::Tensor masked_mean(const torch::Tensor& value, const torch::Tensor& mask) {
  TORCH_CHECK(value.dim() == 4, "value must be [B,C,H,W], got ", value.sizes());
  check_shape(mask, "mask", {value.size(0), 1, value.size(2), value.size(3)});
  const auto denom = (mask.sum() * value.size(1)).clamp_min(1e-12);
  return (value * mask).sum() / denom;
}

}  // namespace geo
