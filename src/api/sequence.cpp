// geo::Model::run_sequence (include/geo/geo.h): a sequence's depth, flow and motion frame by frame,
// three frames held at a time, and the trajectory they chain to. geo_infer and the Python module
// run sequences through it.
#include "geo/geo.h"

#include "api/model_impl.h"
#include "core/lanes.h"

#include <torch/torch.h>

#include <deque>
#include <future>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace geo {

namespace {
// The most frames computed at once on the CPU (plan_lanes): 2 cores give 2 lanes of one thread,
// 16 give 4 lanes of 4.
constexpr int kMaxLanes = 4;
}  // namespace

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
  // Frame i's outputs (its previous, itself, its next): independent of the other frames', so on
  // the CPU several are computed at once (core/lanes.h), each with a share of the threads.
  const auto compute = [this, three, &intrinsics](SequenceFrame f, const torch::Tensor& previous,
                                                  const torch::Tensor& next) {
    if (next.defined() && three) {
      const auto parts = flow_parts(f.image, next, intrinsics, previous);
      f.depth = parts.depth.cpu() * f.scale;
      f.flow = parts.full.cpu();
      f.rigid_flow = parts.rigid.cpu();
      f.motion = parts.motion.cpu();
    } else {
      f.depth = depth(f.image).cpu() * f.scale;
    }
    return f;
  };
  std::vector<torch::Tensor> motions;
  std::vector<double> step_scales;
  const auto hand_on = [&](const SequenceFrame& f) {
    if (f.motion.defined()) {
      motions.push_back(f.motion);
      step_scales.push_back(f.scale);
    }
    sink(f);
  };
  const auto plan = device().is_cpu() ? plan_lanes(at::get_num_threads(), kMaxLanes) : LanePlan{};
  std::optional<Lanes> lanes;
  if (plan.lanes > 1) lanes.emplace(plan);
  // Computed ahead, in order: one more than the lanes, so that a lane has the next frame while this
  // thread hands one on (at most lanes + 3 frames held).
  std::deque<std::future<SequenceFrame>> ahead;
  size_t i = 0;
  for (; current.defined(); ++i) {
    next = next_frame(current);
    SequenceFrame f;
    f.index = i;
    f.image = current;
    f.scale = scale_of(i);
    if (!lanes) {
      hand_on(compute(std::move(f), previous, next));
    } else {
      ahead.push_back(
          lanes->submit([compute, f = std::move(f), previous, next] { return compute(f, previous, next); }));
      if (ahead.size() > static_cast<size_t>(plan.lanes)) {
        hand_on(ahead.front().get());
        ahead.pop_front();
      }
    }
    previous = std::move(current);
    current = std::move(next);
  }
  for (; !ahead.empty(); ahead.pop_front()) hand_on(ahead.front().get());
  if (!scales.empty() && scales.size() != i)
    throw Error("run_sequence: " + std::to_string(scales.size()) + " scales for " + std::to_string(i) + " frames");
  if (motions.empty()) return {};
  return chain_poses(motions, step_scales);
}

}  // namespace geo
