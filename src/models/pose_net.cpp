#include "models/pose_net.h"

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
  pred = register_module("pred", torch::nn::Conv2d(torch::nn::Conv2dOptions(in, 6 * num_sources(), 1)));
  init_weights(*this);
}

torch::Tensor PoseNetImpl::forward(const torch::Tensor& tgt, const std::vector<torch::Tensor>& srcs) {
  TORCH_CHECK(static_cast<int>(srcs.size()) == num_sources(), "PoseNet expects ", num_sources(),
              " source images, got ", srcs.size());
  std::vector<torch::Tensor> frames{tgt};
  for (const auto& s : srcs) {
    TORCH_CHECK(s.sizes() == tgt.sizes(), "PoseNet: source ", s.sizes(), " must match target ",
                tgt.sizes());
    frames.push_back(s);
  }
  TORCH_CHECK(tgt.dim() == 4 && tgt.size(1) == 3, "PoseNet target must be [B,3,H,W], got ", tgt.sizes());
  auto x = normalize_image(torch::cat(frames, 1).to(compute_dtype));
  for (auto& c : convs) x = c(x);
  x = conv2d(*pred, x).mean({2, 3}).to(torch::kFloat32);  // [B, 6N]
  return options.output_scale * x.view({-1, num_sources(), 6});
}

}  // namespace geo
