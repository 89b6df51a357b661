// Camera trajectories of a monocular sequence from its relative poses, in the KITTI pose-file
// convention (camera-to-world, the first frame the identity), optionally each step at a metric scale
// (the camera's height above the fitted road, road_plane.h). One implementation for geo_infer's
// trajectory.txt and the odometry protocol.
#pragma once

#include <torch/torch.h>

#include <functional>
#include <string>
#include <vector>

namespace geo {

class TrajectoryChain {
 public:
  // The step from one frame to the next: `next_from_this` [4,4] maps points in this frame's camera
  // to the next frame's (the PoseNet's source-from-target pose with the next frame as source).
  void add_step(const torch::Tensor& next_from_this);
  size_t steps() const { return steps_.size(); }
  // Camera-to-world poses [steps + 1, 4, 4] float64. `scales` (at least one per step, e.g. from
  // metric_scales) multiply each step's translation; none: the network's own scale.
  torch::Tensor poses(const std::vector<double>& scales = {}) const;

 private:
  std::vector<torch::Tensor> steps_;  // this-to-next camera motion, as camera-to-world increments
};

// Per-frame metric scales from per-frame estimates (camera_height_scale: 0 where the road was not
// found), smoothed over 11 frames (smooth_scales); a frame with no estimate within 5 frames takes the
// smoothed scale of the nearest frame that has one. Throws std::runtime_error with `no_road(0)` when
// no frame has an estimate.
std::vector<double> metric_scales(const std::vector<double>& per_frame,
                                  const std::function<std::string(size_t)>& no_road);

}  // namespace geo
