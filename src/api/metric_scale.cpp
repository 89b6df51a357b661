// geo::Model's metric scale (include/geo/geo.h): depth and motion in metres from the camera's height
// above the road plane fitted to the predicted depth, per frame and smoothed over a sequence.
#include "api/model_impl.h"
#include "geometry/road_plane.h"
#include "geometry/trajectory.h"

#include <cmath>
#include <string>
#include <vector>

namespace geo {

torch::Tensor kitti_like_intrinsics(int64_t height, int64_t width) {
  const double h = static_cast<double>(height), w = static_cast<double>(width);
  return torch::tensor({0.58 * w, 0.0, 0.5 * w, 0.0, 1.92 * h, 0.5 * h, 0.0, 0.0, 1.0}, torch::kFloat64).view({3, 3});
}

namespace {
void check_camera_height(double camera_height) {
  if (!(camera_height > 0) || !std::isfinite(camera_height))
    throw Error("camera_height must be a positive number of metres, got " + std::to_string(camera_height));
}

// Each frame's smoothed scale (geometry/trajectory.h metric_scales); `hint` follows the message
// naming a frame without a road near it.
std::vector<double> smoothed_scales(const std::vector<double>& per_frame, const std::string& hint) {
  return guarded("smooth_road_scales", [&] {
    return metric_scales(per_frame, [&](size_t i) {
      return "no road plane in any frame near frame " + std::to_string(i) + " of " + std::to_string(per_frame.size()) +
             hint + ": metric scale needs a flat road in front of the camera";
    });
  });
}
}  // namespace

torch::Tensor Model::metric_depth(const torch::Tensor& image, double camera_height, const torch::Tensor& intrinsics,
                                  std::vector<double>* scale) const {
  const auto depth = this->depth(image);
  return guarded("geo::Model::metric_depth", [&] {
    torch::InferenceMode guard;
    check_camera_height(camera_height);
    const bool batched = depth.dim() == 3;
    const int64_t B = batched ? depth.size(0) : 1, H = depth.size(-2), W = depth.size(-1);
    // Not given: the learned camera (a batch's mean), else KITTI's proportions.
    const auto K = intrinsics.defined() ? checked_intrinsics(intrinsics, H, W, false)
                   : spec().learns_intrinsics
                       ? (batched ? this->intrinsics(image, image).mean(0) : this->intrinsics(image, image))
                       : kitti_like_intrinsics(H, W);
    auto out = depth.clone();
    if (scale) scale->clear();
    for (int64_t b = 0; b < B; ++b) {
      auto d = batched ? out[b] : out;
      const auto plane = fit_road_plane(d.cpu(), K);
      if (!plane.found)
        throw Error("no road plane in the lower image" +
                    std::string(batched ? " of batch item " + std::to_string(b) : "") + ": " + plane.why +
                    " (metric depth needs a flat road in front of the camera)");
      const double s = camera_height_scale(plane, camera_height);
      d.mul_(s);
      if (scale) scale->push_back(s);
    }
    return out;
  });
}

std::vector<double> Model::sequence_scales(const std::vector<torch::Tensor>& frames, double camera_height,
                                           const torch::Tensor& intrinsics, std::vector<size_t>* without_road) const {
  TensorFrames source(frames);
  return sequence_scales(source, camera_height, intrinsics, without_road);
}

std::vector<double> Model::sequence_scales(FrameSource& frames, double camera_height, const torch::Tensor& intrinsics,
                                           std::vector<size_t>* without_road) const {
  guarded("geo::Model::sequence_scales", [&] { check_camera_height(camera_height); });
  if (without_road) without_road->clear();
  std::vector<double> per_frame;
  frames.restart();
  torch::Tensor frame;
  for (size_t i = 0; frames.next(frame); ++i) {
    if (frame.dim() != 3)
      throw Error("sequence_scales takes one image per frame ([3,H,W]), frame " + std::to_string(i) + " is " +
                  c10::str(frame.sizes()));
    per_frame.push_back(road_scale(frame, camera_height, intrinsics));
    if (!(per_frame.back() > 0) && without_road) without_road->push_back(i);
  }
  return smoothed_scales(per_frame, intrinsics.defined() || spec().learns_intrinsics
                                        ? ""
                                        : " (with the default KITTI-like camera: give the intrinsics)");
}

double Model::road_scale(const torch::Tensor& frame, double camera_height, const torch::Tensor& intrinsics) const {
  guarded("geo::Model::road_scale", [&] { check_camera_height(camera_height); });  // before the DepthNet runs
  const auto d = depth(frame);
  return guarded("geo::Model::road_scale", [&] {
    if (d.dim() != 2) throw Error("road_scale takes one image ([3,H,W]), got " + c10::str(frame.sizes()));
    const auto K = intrinsics.defined()       ? checked_intrinsics(intrinsics, d.size(0), d.size(1), false)
                   : spec().learns_intrinsics ? this->intrinsics(frame, frame)
                                              : kitti_like_intrinsics(d.size(0), d.size(1));
    const auto plane = fit_road_plane(d.cpu(), K);
    return plane.found ? camera_height_scale(plane, camera_height) : 0.0;
  });
}

std::vector<double> smooth_road_scales(const std::vector<double>& road_scales) {
  return smoothed_scales(road_scales, "");
}

torch::Tensor chain_poses(const std::vector<torch::Tensor>& motions, const std::vector<double>& scales) {
  return guarded("chain_poses", [&] {
    if (!scales.empty() && scales.size() != motions.size())
      throw Error("chain_poses: " + std::to_string(motions.size()) + " motions and " + std::to_string(scales.size()) +
                  " scales (one per step, or none)");
    TrajectoryChain chain;
    for (size_t i = 0; i < motions.size(); ++i) {
      if (motions[i].sizes() != torch::IntArrayRef{4, 4})
        throw Error("chain_poses: motion " + std::to_string(i) + " must be [4,4], got " + c10::str(motions[i].sizes()));
      chain.add_step(motions[i]);
    }
    return chain.poses(scales);
  });
}

}  // namespace geo
