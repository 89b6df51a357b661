#include "geometry/trajectory.h"

#include "geometry/road_plane.h"

#include <stdexcept>

namespace geo {

void TrajectoryChain::add_step(const torch::Tensor& next_from_this) {
  TORCH_CHECK(next_from_this.sizes() == torch::IntArrayRef({4, 4}), "a trajectory step must be [4,4], got ",
              next_from_this.sizes());
  steps_.push_back(torch::inverse(next_from_this.to(torch::kCPU, torch::kFloat64)));
}

torch::Tensor TrajectoryChain::poses(const std::vector<double>& scales) const {
  TORCH_CHECK(scales.empty() || scales.size() >= steps_.size(), "a trajectory of ", steps_.size(),
              " steps needs as many scales, got ", scales.size());
  std::vector<torch::Tensor> out = {torch::eye(4, torch::kFloat64)};
  for (size_t j = 0; j < steps_.size(); ++j) {
    auto step = steps_[j];
    if (!scales.empty()) {
      step = step.clone();
      step.slice(0, 0, 3).select(1, 3).mul_(scales[j]);
    }
    out.push_back(out.back().matmul(step));
  }
  return torch::stack(out);
}

std::vector<double> metric_scales(const std::vector<double>& per_frame,
                                  const std::function<std::string(size_t)>& no_road) {
  auto scales = smooth_scales(per_frame, 5);
  // A longer stretch without a road (the car ahead hiding it, a turn) takes the scale of the nearest
  // frame that has one (the earlier on a tie): the scene's scale does not jump there.
  const auto n = static_cast<int64_t>(scales.size());
  const auto found = [&](int64_t j) { return j >= 0 && j < n && scales[static_cast<size_t>(j)] > 0; };
  auto out = scales;
  for (int64_t i = 0; i < n; ++i) {
    if (found(i)) continue;
    for (int64_t d = 1; d < n; ++d) {
      if (found(i - d)) {
        out[static_cast<size_t>(i)] = scales[static_cast<size_t>(i - d)];
        break;
      }
      if (found(i + d)) {
        out[static_cast<size_t>(i)] = scales[static_cast<size_t>(i + d)];
        break;
      }
    }
    if (!(out[static_cast<size_t>(i)] > 0)) throw std::runtime_error(no_road(static_cast<size_t>(i)));
  }
  return out;
}

}  // namespace geo
