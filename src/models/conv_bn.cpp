#include "models/conv_bn.h"

#include <torch/version.h>

#include "core/runtime.h"
#include "models/layers.h"
#include "models/upsample_conv.h"

namespace geo {

ConvBnImpl::ConvBnImpl(int64_t in, int64_t out, int64_t kernel, int64_t stride, bool relu_, bool upsampled_)
    : relu(relu_), upsampled(upsampled_) {
  conv = register_module(
      "conv", Conv2d(torch::nn::Conv2dOptions(in, out, kernel).stride(stride).padding(kernel / 2).bias(false)));
  bn = register_module("bn", SyncBatchNorm2d(out));
}

torch::Tensor ConvBnImpl::conv_bn_relu(const torch::Tensor& x, const ConvFn& conv_fn) {
  torch::Tensor y;
  if (folded()) {
    TORCH_CHECK(!is_training(), "ConvBn: BatchNorm was folded for inference; this module cannot train");
    y = conv_fn(x, folded_weight(), folded_bias_);
  } else {
    const auto c = conv_fn(x, conv->weight, conv->bias);
    y = bn(c);
  }
  return relu ? torch::relu(y) : y;
}

namespace {

// A convolution with kernels prepacked by at::mkldnn_reorder_conv2d_weight: the activations are
// reordered into oneDNN's layout and back, the weights not.
torch::Tensor packed_conv(const torch::Tensor& x, const torch::Tensor& weight, const torch::Tensor& bias,
                          torch::IntArrayRef padding, torch::IntArrayRef stride) {
  return at::mkldnn_convolution(x.contiguous().to_mkldnn(), weight, bias, padding, stride, {1, 1}, 1).to_dense();
}

}  // namespace

bool ConvBnImpl::uses_packed(const torch::Tensor& x, bool packed) const {
  if (!packed || !x.device().is_cpu() || x.scalar_type() != folded_bias_.scalar_type()) return false;
  TORCH_CHECK(!is_training(), "ConvBn: BatchNorm was folded for inference; this module cannot train");
  return true;
}

namespace {
constexpr const char* kReleased = "ConvBn: its float kernel was let go for int8-only inference; it runs in int8 only";
}  // namespace

void ConvBnImpl::prepack_once(const torch::Tensor& x) {
  TORCH_CHECK(!released_, kReleased);
  if (!pack_pending_) return;
  std::call_once(pack_once_, [this, &x] {
    torch::NoGradGuard no_grad;
    // (float32: the kernel computed from the parameters now; bf16: kept from folding)
    const auto w32 = pending_w32_.defined() ? pending_w32_ : folded_weight();
    const auto kernel = folded_weight_.defined() ? folded_weight_ : w32;
    prepack(kernel, w32, pending_b32_, pad_channels(x, onednn_channel_padding(x)).sizes());
    // Packed: folded_weight() computes the plain kernel again when asked; not packed: kept for the calls.
    folded_weight_ = prepacked() ? torch::Tensor() : kernel;
    pending_w32_ = pending_b32_ = torch::Tensor();
  });
}

torch::Tensor ConvBnImpl::forward(const torch::Tensor& x) {
  prepack_once(x);
  const auto& o = conv->options;
  const auto k = *o.kernel_size();
  const int64_t pad = onednn_channel_padding(x);
  if (uses_packed(x, static_cast<bool>(packed_conv_))) return packed_conv_(pad_channels(x, pad));
  if (uses_packed(x, packed_weight_.defined())) {  // (packed with the padded channels)
    const auto y = packed_conv(pad_channels(x, pad), packed_weight_, packed_bias_, {k[0] / 2, k[1] / 2}, *o.stride());
    return relu ? torch::relu(y) : y;
  }
  return conv_bn_relu(x, [&](const torch::Tensor& in, const torch::Tensor& w, const torch::Tensor& b) {
    return conv2d(in, w, b, *o.stride(), {k[0] / 2, k[1] / 2});  // padding as constructed
  });
}

torch::Tensor ConvBnImpl::forward_upsampled(const torch::Tensor& x) {
  const auto& o = conv->options;
  TORCH_CHECK(
      (*o.kernel_size())[0] == 3 && (*o.kernel_size())[1] == 3 && (*o.stride())[0] == 1 && (*o.stride())[1] == 1,
      "forward_upsampled needs a 3x3 stride-1 ConvBn");
  if (x.size(2) * x.size(3) < kMinSubpixelArea) return forward(upsample2(x, UpsampleMode::kNearest));
  prepack_once(x);
  const int64_t B = x.size(0), Co = conv->weight.size(0), h = x.size(2), w = x.size(3);
  if (uses_packed(x, packed_phase_weight_.defined())) {
    const auto phases =
        packed_conv(x, packed_phase_weight_, packed_phase_bias_, {1, 1}, {1, 1}).view({B, 2, 2, Co, h + 1, w + 1});
    // float32: channels-last, as the prepacked convolutions after it read; bf16's read the dense order.
    if (packed_conv_) return interleave_phases_channels_last(phases, relu);
    const auto y = interleave_phases(phases);
    return relu ? torch::relu(y) : y;
  }
  return conv_bn_relu(x, conv3x3_of_upsampled);
}

void ConvBnImpl::fold_batchnorm(torch::Dtype dtype) {
  if (folded()) return;
  torch::NoGradGuard no_grad;
  const auto bias = bn->bias - bn->running_mean * bn_scale();
  folded_bias_ = bias.to(dtype);
  const bool onednn = conv->weight.device().is_cpu() && at::hasMKLDNN() && at::globalContext().userEnabledMkldnn();
  // In float32 with oneDNN the folded kernel is computed where it is used (packed at the first float
  // call, quantized by the int8 path) from the parameters, which stay float32: a model that runs in
  // int8 never holds a float copy of its kernels beside the parameters.
  if (onednn && dtype == torch::kFloat32) {
    pending_b32_ = folded_bias_;
    pack_pending_ = true;
    return;
  }
  const auto weight = scaled_kernel();
  folded_weight_ = weight.to(dtype).contiguous();
  if (onednn) {
    pending_w32_ = weight;                    // packed at the first call (prepack_once)
    pending_b32_ = bias.to(torch::kFloat32);  // oneDNN adds a float32 bias to bf16 products
    pack_pending_ = true;
  }
}

torch::Tensor ConvBnImpl::folded_weight() const {
  TORCH_CHECK(!released_, kReleased);
  if (folded_weight_.defined() || !folded()) return folded_weight_;
  torch::NoGradGuard no_grad;
  return scaled_kernel().to(folded_bias_.scalar_type()).contiguous();
}

void ConvBnImpl::release_float_kernel() {
  TORCH_CHECK(folded() && !is_training(), "ConvBn: only a folded module (inference) lets go of its float kernel");
  torch::NoGradGuard no_grad;
  release_float_weight(conv->weight);
  folded_weight_ = pending_w32_ = torch::Tensor();
  packed_weight_ = packed_phase_weight_ = packed_bias_ = packed_phase_bias_ = torch::Tensor();
  packed_conv_ = PrepackedConv();
  released_ = true;
}

torch::Tensor ConvBnImpl::bn_scale() const { return bn->weight / torch::sqrt(bn->running_var + bn->options.eps()); }

torch::Tensor ConvBnImpl::scaled_kernel() const { return conv->weight * bn_scale().view({-1, 1, 1, 1}); }

void ConvBnImpl::prepack(const torch::Tensor& kernel, const torch::Tensor& w32, const torch::Tensor& b32,
                         torch::IntArrayRef input) {
  const auto& o = conv->options;
  const auto k = *o.kernel_size();
  const std::vector<int64_t> pad = {k[0] / 2, k[1] / 2};
  const bool phases = upsampled && k[0] == 3 && k[1] == 3 && (*o.stride())[0] == 1 && (*o.stride())[1] == 1;
  const auto w = pad_channels(kernel, onednn_channel_padding(kernel));  // as forward pads x
  // float32: the convolution as oneDNN's prepacked one (ReLU fused, channels-last in and out). The
  // phase kernels stay blocked: oneDNN's channels-last 2x2 convolutions sum in an order that depends
  // on the number of threads, so a 1- and a 2-thread run would differ in the last bits.
  if (kernel.scalar_type() == torch::kFloat32)
    packed_conv_ = PrepackedConv::make(w, b32, *o.stride(), pad, input, relu);
  try {
    if (!packed_conv_) {
      packed_weight_ = at::mkldnn_reorder_conv2d_weight(w.contiguous().to_mkldnn(), pad, *o.stride(), {1, 1}, 1);
      packed_bias_ = b32;
    }
    if (phases) {
      packed_phase_weight_ = at::mkldnn_reorder_conv2d_weight(
          phase_kernels(w32).to(kernel.scalar_type()).contiguous().to_mkldnn(), {1, 1}, {1, 1}, {1, 1}, 1);
      packed_phase_bias_ = b32.repeat({4});
    }
    // A CPU without oneDNN's kernels for this type (bf16 without AVX-512) fails here, not later.
    if (!packed_conv_)
      packed_conv(torch::zeros({1, w.size(1), k[0], k[1]}, kernel.options()), packed_weight_, packed_bias_, pad,
                  *o.stride());
  } catch (const c10::Error&) {
    packed_weight_ = packed_phase_weight_ = packed_bias_ = packed_phase_bias_ = torch::Tensor();
  }
}

int fold_batchnorm(torch::nn::Module& module, torch::Dtype dtype) {
  int n = 0;
  for (auto& m : module.modules(/*include_self=*/true)) {
    if (auto* cb = m->as<ConvBnImpl>()) {
      cb->fold_batchnorm(dtype);
      ++n;
    }
  }
  return n;
}

}  // namespace geo
