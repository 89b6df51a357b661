#include "models/upsample_conv.h"

#include <torch/autograd.h>

#include <mutex>
#include <vector>

#include "models/conv.h"

namespace geo {

namespace {

// [16, 9]: row (a, b, u, v) = phase (a, b), tap (u, v) of the 2x2 phase kernel; column (k, l) = tap
// of the 3x3 kernel. Along one dim, phase 0 has taps (w0, w1 + w2), phase 1 (w0 + w1, w2).
// Made once per device and type: on a GPU a copy from the host per call would wait for the
// device, and cannot be part of a CUDA graph (core/cuda_graph.h).
torch::Tensor phase_matrix(const torch::TensorOptions& options) {
  static std::mutex mutex;
  static std::vector<torch::Tensor> made;
  const std::lock_guard<std::mutex> lock(mutex);
  for (const auto& m : made)
    if (m.device() == options.device() && m.dtype() == options.dtype()) return m;
  static const float P[2][2][3] = {{{1, 0, 0}, {0, 1, 1}}, {{1, 1, 0}, {0, 0, 1}}};
  const c10::InferenceMode normal_tensor(false);  // usable in training too, whoever asks first
  auto m = torch::zeros({16, 9}, torch::kFloat32);
  auto acc = m.accessor<float, 2>();
  for (int a = 0; a < 2; ++a)
    for (int b = 0; b < 2; ++b)
      for (int u = 0; u < 2; ++u)
        for (int v = 0; v < 2; ++v)
          for (int k = 0; k < 3; ++k)
            for (int l = 0; l < 3; ++l) acc[((a * 2 + b) * 2 + u) * 2 + v][k * 3 + l] = P[a][u][k] * P[b][v][l];
  made.push_back(m.to(options));
  return made.back();
}

// y [B,2,2,Co,h+1,w+1] (phase (a, b) of output pixel (2i+a, 2j+b) at y[:, a, b, :, i+a, j+b])
// -> [B,Co,2h,2w]. Written as one autograd node: its backward copies the four windows into one
// gradient buffer (slicing y with select/narrow instead costs a zero-filled y-sized buffer and an
// addition per phase in the backward pass).
struct InterleavePhases : torch::autograd::Function<InterleavePhases> {
  // (relu: the image gets max(window, 0); inference's channels-last interleave)
  static void copy_windows(const torch::Tensor& phases, const torch::Tensor& image6, int64_t h, int64_t w,
                           bool to_image, bool relu = false) {
    for (int64_t a = 0; a < 2; ++a)
      for (int64_t b = 0; b < 2; ++b) {
        auto window = phases.select(1, a).select(1, b).narrow(2, a, h).narrow(3, b, w);
        auto pixels = image6.select(5, b).select(3, a);
        if (!to_image) window.copy_(pixels);
        else if (relu) at::clamp_min_out(pixels, window, 0);
        else pixels.copy_(window);
      }
  }
  static torch::Tensor forward(torch::autograd::AutogradContext* ctx, const torch::Tensor& y) {
    const int64_t B = y.size(0), Co = y.size(3), h = y.size(4) - 1, w = y.size(5) - 1;
    ctx->saved_data["shape"] = y.sizes().vec();
    auto out = torch::empty({B, Co, h, 2, w, 2}, y.options());
    copy_windows(y, out, h, w, /*to_image=*/true);
    return out.view({B, Co, 2 * h, 2 * w});
  }
  static torch::autograd::variable_list backward(torch::autograd::AutogradContext* ctx,
                                                 torch::autograd::variable_list grads) {
    const auto shape = ctx->saved_data["shape"].toIntVector();
    const int64_t B = shape[0], Co = shape[3], h = shape[4] - 1, w = shape[5] - 1;
    const auto g = grads[0].contiguous().view({B, Co, h, 2, w, 2});
    auto gy = torch::empty(shape, g.options());
    copy_windows(gy, g, h, w, /*to_image=*/false);
    for (int64_t a = 0; a < 2; ++a)  // the row and column each phase does not use
      for (int64_t b = 0; b < 2; ++b) {
        auto p = gy.select(1, a).select(1, b);
        p.select(2, a == 0 ? h : 0).zero_();
        p.select(3, b == 0 ? w : 0).zero_();
      }
    return {gy};
  }
};

}  // namespace

torch::Tensor phase_kernels(const torch::Tensor& weight) {
  const int64_t Co = weight.size(0), Ci = weight.size(1);
  // The four 2x2 phase kernels as one matrix product (backward: one small GEMM, not a
  // zero-filled weight-sized buffer per selected tap): [Co*Ci, 9] x [9, 16] -> [4*Co, Ci, 2, 2].
  return weight.reshape({Co * Ci, 9})
      .matmul(phase_matrix(weight.options()).t())
      .view({Co, Ci, 4, 2, 2})
      .permute({2, 0, 1, 3, 4})
      .reshape({4 * Co, Ci, 2, 2});
}

torch::Tensor interleave_phases(const torch::Tensor& phases) { return InterleavePhases::apply(phases); }

torch::Tensor interleave_phases_channels_last(const torch::Tensor& phases, bool relu) {
  TORCH_CHECK(phases.dim() == 6 && phases.size(1) == 2 && phases.size(2) == 2,
              "interleave_phases_channels_last: phases must be [B,2,2,Co,h+1,w+1], got ", phases.sizes());
  const int64_t B = phases.size(0), Co = phases.size(3), h = phases.size(4) - 1, w = phases.size(5) - 1;
  auto out = torch::empty({B, Co, 2 * h, 2 * w}, phases.options().memory_format(at::MemoryFormat::ChannelsLast));
  // (splitting rows and columns keeps the channels-last strides)
  InterleavePhases::copy_windows(phases, out.view({B, Co, h, 2, w, 2}), h, w, /*to_image=*/true, relu);
  return out;
}

torch::Tensor conv3x3_of_upsampled(const torch::Tensor& x, const torch::Tensor& weight, const torch::Tensor& bias) {
  TORCH_CHECK(
      x.dim() == 4 && weight.dim() == 4 && weight.size(2) == 3 && weight.size(3) == 3 && weight.size(1) == x.size(1),
      "conv3x3_of_upsampled: x ", x.sizes(), " and weight ", weight.sizes(), " do not match");
  const int64_t B = x.size(0), Co = weight.size(0), h = x.size(2), w = x.size(3);
  const auto kernels = phase_kernels(weight);
  const auto b4 = bias.defined() ? bias.repeat({4}) : bias;
  // With padding 1 a 2x2 kernel gives (h+1)x(w+1) outputs; output r reads input rows r-1, r.
  // Phase a = 0 needs rows (i-1, i): r = i; phase a = 1 needs (i, i+1): r = i + 1.
  const auto y = conv2d(x, kernels, b4, {1, 1}, {1, 1}).view({B, 2, 2, Co, h + 1, w + 1});
  return interleave_phases(y);
}

}  // namespace geo
