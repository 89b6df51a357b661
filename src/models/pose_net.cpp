#include "models/pose_net.h"

#include "models/graph.h"
#include "models/layers.h"

namespace geo {

PoseNetImpl::PoseNetImpl(const PoseNetOptions& o) : options(o) {
  TORCH_CHECK(o.seq_length >= 2, "PoseNet seq_length must be >= 2, got ", o.seq_length);
  const int64_t widths[7] = {16, 32, 64, 128, 256, 256, 256};  // GeoNet / paper
  const int64_t kernels[7] = {7, 5, 3, 3, 3, 3, 3};
  int64_t in = 3 * o.seq_length;
  for (int i = 0; i < 7; ++i) {
    convs.push_back(register_module("conv" + std::to_string(i + 1), ConvBn(in, widths[i], kernels[i], 2)));
    in = widths[i];
  }
  pred = register_module("pred", Conv2d(torch::nn::Conv2dOptions(in, 6 * num_sources(), 1)));
  if (o.learn_intrinsics) intrinsics = register_module("intrinsics", Conv2d(torch::nn::Conv2dOptions(in, 4, 1)));
  init_weights(*this);
  if (intrinsics) {  // start at fx = fy = ln 2 W, principal point centred
    torch::NoGradGuard no_grad;
    intrinsics->weight.zero_();
    intrinsics->bias.zero_();
  }
}

torch::Tensor PoseNetImpl::forward(const torch::Tensor& tgt, const std::vector<torch::Tensor>& srcs) {
  return predict(tgt, srcs).poses;
}

PoseOutput PoseNetImpl::predict(const torch::Tensor& tgt, const std::vector<torch::Tensor>& srcs) {
  TORCH_CHECK(static_cast<int>(srcs.size()) == num_sources(), "PoseNet expects ", num_sources(), " source images, got ",
              srcs.size());
  std::vector<torch::Tensor> frames{tgt};
  for (const auto& s : srcs) {
    TORCH_CHECK(s.sizes() == tgt.sizes(), "PoseNet: source ", s.sizes(), " must match target ", tgt.sizes());
    frames.push_back(s);
  }
  TORCH_CHECK(tgt.dim() == 4 && tgt.size(1) == 3, "PoseNet target must be [B,3,H,W], got ", tgt.sizes());
  auto x = normalize_image(torch::cat(frames, 1).to(compute_dtype));
  if (int8) {
    x = int8->forward(x);
  } else {
    FloatOps ops;
    x = pose_graph(*this, ops, x);
  }
  PoseOutput out;
  if (intrinsics) {
    // Scaled as the poses are (intrinsics_output_scale: why, in pose_net.h).
    const auto v = options.intrinsics_output_scale *
                   conv2d(*intrinsics, x.mean({2, 3}, true)).flatten(1).to(torch::kFloat32);  // [B,4]
    const double W = static_cast<double>(tgt.size(3)), H = static_cast<double>(tgt.size(2));
    const auto fx = torch::softplus(v.select(1, 0)) * W, fy = torch::softplus(v.select(1, 1)) * W;
    const auto cx = (v.select(1, 2) + 0.5) * W, cy = (v.select(1, 3) + 0.5) * H;
    const auto zero = torch::zeros_like(fx), one = torch::ones_like(fx);
    out.K = torch::stack({fx, zero, cx, zero, fy, cy, zero, zero, one}, 1).view({-1, 3, 3});
  }
  x = conv2d(*pred, x).mean({2, 3}).to(torch::kFloat32);  // [B, 6N]
  out.poses = options.output_scale * x.view({-1, num_sources(), 6});
  return out;
}

}  // namespace geo
