// geo::Model::run_sequence (include/geo/geo.h): a sequence's depth, flow and motion frame by frame,
// three frames held at a time, and the trajectory they chain to. geo_infer and the Python module
// run sequences through it.
#include "geo/geo.h"

#include "api/model_impl.h"

#include <torch/torch.h>

#include <string>
#include <utility>
#include <vector>

namespace geo {

torch::Tensor Model::run_sequence(FrameSource& frames, const std::function<void(const SequenceFrame&)>& sink,
                                  const std::vector<double>& scales, const torch::Tensor& intrinsics) const {
  const bool three = spec().seq_length == 3;
  frames.restart();
  size_t read = 0;
  // The next frame, checked against the first one's size; undefined after the last.
  auto next_frame = [&](const torch::Tensor& first) {
    torch::Tensor frame;
    if (!frames.next(frame)) return torch::Tensor();
    if (!frame.defined() || frame.dim() != 3 || (first.defined() && frame.sizes() != first.sizes()))
      throw Error("run_sequence: frame " + std::to_string(read) + " is " +
                  (frame.defined() ? c10::str(frame.sizes()) : std::string("undefined")) + ", expected " +
                  (first.defined() ? c10::str(first.sizes()) : std::string("an image [3,H,W]")) +
                  " (one camera: every frame of one size)");
    ++read;
    return frame;
  };
  torch::Tensor previous, current = next_frame({}), next;
  if (!current.defined()) throw Error("run_sequence: the source gave no frame");
  const auto scale_of = [&](size_t i) {
    if (scales.empty()) return 1.0;
    if (i >= scales.size())
      throw Error("run_sequence: " + std::to_string(scales.size()) + " scales for a sequence of more frames");
    return scales[i];
  };
  std::vector<torch::Tensor> motions;
  std::vector<double> step_scales;
  size_t i = 0;
  for (; current.defined(); ++i) {
    next = next_frame(current);
    SequenceFrame f;
    f.index = i;
    f.image = current;
    f.scale = scale_of(i);
    if (next.defined() && three) {
      const auto parts = flow_parts(current, next, intrinsics, previous);
      f.depth = parts.depth.cpu() * f.scale;
      f.flow = parts.full.cpu();
      f.rigid_flow = parts.rigid.cpu();
      f.motion = parts.motion.cpu();
      motions.push_back(f.motion);
      step_scales.push_back(f.scale);
    } else {
      f.depth = depth(current).cpu() * f.scale;
    }
    sink(f);
    previous = std::move(current);
    current = std::move(next);
  }
  if (!scales.empty() && scales.size() != i)
    throw Error("run_sequence: " + std::to_string(scales.size()) + " scales for " + std::to_string(i) + " frames");
  if (motions.empty()) return {};
  return chain_poses(motions, step_scales);
}

}  // namespace geo
