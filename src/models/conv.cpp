#include "models/conv.h"

#include <torch/version.h>

#include "core/runtime.h"

namespace geo {

void release_float_weight(torch::Tensor& weight) {
  torch::NoGradGuard no_grad;
  weight.set_data(torch::empty({0}, weight.options()));
}

int64_t onednn_channel_padding(const torch::Tensor& x) {
#if TORCH_VERSION_MAJOR >= 2
  const int64_t c = x.dim() == 4 ? x.size(1) : 0;
  if (!x.device().is_cpu() || c == 0 || c % 16 == 0) return 0;
  if (c == 1 || c > 16) return 16 - c % 16;
  // 2..15 channels: only the input's gradient in bfloat16 is wrong.
  const bool bf16 = x.scalar_type() == torch::kBFloat16 || autocast_enabled(torch::kCPU);
  if (bf16 && x.requires_grad() && torch::GradMode::is_enabled()) return 16 - c;
#endif
  return 0;
}

torch::Tensor pad_channels(const torch::Tensor& t, int64_t n) {
  return n > 0 ? torch::constant_pad_nd(t, {0, 0, 0, 0, 0, n}) : t;
}

torch::Tensor conv2d(const torch::Tensor& x, const torch::Tensor& weight, const torch::Tensor& bias,
                     torch::IntArrayRef stride, torch::IntArrayRef padding) {
  const int64_t in_pad = onednn_channel_padding(x);
  int64_t out_pad = 0;
#if TORCH_VERSION_MAJOR >= 2
  const int64_t co = weight.size(0);
  if (x.device().is_cpu() && co % 16 != 0) out_pad = 16 - co % 16;
#endif
  // Dilation spelled out as {1, 1}: the profiler counts a convolution's FLOPs (geo_bench) only when
  // its padding and dilation have one entry per dimension.
  if (in_pad == 0 && out_pad == 0) return torch::conv2d(x, weight, bias, stride, padding, {1, 1});
  const auto w = torch::constant_pad_nd(weight, {0, 0, 0, 0, 0, in_pad, 0, out_pad});
  const auto b = bias.defined() && out_pad > 0 ? torch::constant_pad_nd(bias, {0, out_pad}) : bias;
  const auto y = torch::conv2d(pad_channels(x, in_pad), w, b, stride, padding, {1, 1});
  return out_pad > 0 ? y.narrow(1, 0, weight.size(0)) : y;
}

namespace {
thread_local bool g_uninitialised = false;

// `o` with one input and one output channel: a placeholder whose initialisation draws next to
// nothing, given the real shapes right after (UninitialisedWeights).
torch::nn::Conv2dOptions placeholder(torch::nn::Conv2dOptions o) { return o.in_channels(1).out_channels(1).groups(1); }
}  // namespace

UninitialisedWeights::UninitialisedWeights() : previous_(g_uninitialised) { g_uninitialised = true; }
UninitialisedWeights::~UninitialisedWeights() { g_uninitialised = previous_; }
bool UninitialisedWeights::active() { return g_uninitialised; }

Conv2dImpl::Conv2dImpl(const torch::nn::Conv2dOptions& o)
    : torch::nn::Conv2dImpl(g_uninitialised ? placeholder(o) : o) {
  if (!g_uninitialised) return;
  options.in_channels(o.in_channels()).out_channels(o.out_channels()).groups(o.groups());
  torch::NoGradGuard no_grad;
  std::vector<int64_t> shape = {o.out_channels(), o.in_channels() / o.groups()};
  shape.insert(shape.end(), (*o.kernel_size()).begin(), (*o.kernel_size()).end());
  weight.set_data(torch::empty(shape));
  if (bias.defined()) bias.set_data(torch::empty({o.out_channels()}));
}

torch::Tensor conv2d(const torch::nn::Conv2dImpl& m, const torch::Tensor& x) {
  const auto& o = m.options;
  TORCH_CHECK(o.groups() == 1 && (*o.dilation())[0] == 1 && (*o.dilation())[1] == 1,
              "geo::conv2d: grouped or dilated convolutions are not supported");
#if TORCH_VERSION_MAJOR >= 2
  const auto* pad = std::get_if<torch::ExpandingArray<2>>(&o.padding());
#else
  const auto* pad = c10::get_if<torch::ExpandingArray<2>>(&o.padding());
#endif
  TORCH_CHECK(pad != nullptr, "geo::conv2d: the padding must be given in pixels");
  return conv2d(x, m.weight, m.bias, *o.stride(), **pad);
}

}  // namespace geo
