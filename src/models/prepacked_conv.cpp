#include "models/prepacked_conv.h"

#include <ATen/core/dispatch/Dispatcher.h>

#include <optional>
#include <string>
#include <vector>

namespace geo {

namespace {

const std::optional<c10::OperatorHandle>& op(bool run) {
  auto find = [](const char* name) -> std::optional<c10::OperatorHandle> {
    auto h = c10::Dispatcher::singleton().findSchema({name, ""});
    if (!h) return std::nullopt;
    return *h;
  };
  static const std::optional<c10::OperatorHandle> prepack = find("mkldnn_prepacked::conv2d_prepack");
  static const std::optional<c10::OperatorHandle> conv_run = find("mkldnn_prepacked::conv2d_run");
  return run ? conv_run : prepack;
}

}  // namespace

PrepackedConv PrepackedConv::make(const torch::Tensor& weight, const torch::Tensor& bias, torch::IntArrayRef stride,
                                  torch::IntArrayRef padding, torch::IntArrayRef input, bool relu) {
  PrepackedConv c;
  if (!op(false) || !op(true) || !at::hasMKLDNN() || !weight.device().is_cpu() ||
      weight.scalar_type() != torch::kFloat32 || weight.dim() != 4 || input.size() != 4)
    return c;
  torch::NoGradGuard no_grad;
  // A copy of its own: the context keeps the kernel it was made from (for LibTorch's unpacking,
  // which nothing here calls) beside the packed one; its storage is let go below.
  auto kernel = weight.clone(at::MemoryFormat::ChannelsLast);
  std::vector<c10::IValue> stack{kernel,
                                 bias.defined() ? c10::IValue(bias.contiguous()) : c10::IValue(),
                                 stride.vec(),
                                 padding.vec(),
                                 std::vector<int64_t>{1, 1},
                                 int64_t{1},
                                 input.vec(),
                                 std::string(relu ? "relu" : "none")};
  try {
    op(false)->callBoxed(&stack);
    c.context_ = std::move(stack.at(0));
    kernel.set_();  // (the context's handle is this tensor: a model holds its kernels once packed)
    // A CPU where oneDNN cannot run it fails here, not at the first frame.
    c(torch::zeros({1, weight.size(1), weight.size(2), weight.size(3)}, weight.options()));
  } catch (const c10::Error&) {
    c.context_ = c10::IValue();
  }
  return c;
}

torch::Tensor PrepackedConv::operator()(const torch::Tensor& x) const {
  TORCH_CHECK(*this, "PrepackedConv: none was made");
  std::vector<c10::IValue> stack{x.contiguous(at::MemoryFormat::ChannelsLast), context_};
  op(true)->callBoxed(&stack);
  return stack.at(0).toTensor();
}

}  // namespace geo
