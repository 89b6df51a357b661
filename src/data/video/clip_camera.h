// The camera of a clip (data.camera) as K at the clip's original frame size: given as
// [fx, fy, cx, cy] pixels, a KITTI calibration file (raw calib_cam_to_cam.txt: P_rect_02;
// odometry calib.txt: P2) or a horizontal field of view. What resizing and cropping do to it is
// geometry/camera.h's cropped_resized_intrinsics.
#pragma once

#include "core/config.h"

#include <torch/torch.h>

#include <string>

namespace geo {

// K [3,3] float64 for frames of width x height. Throws ConfigError naming the key, the value and
// the clip: no camera given, a calibration file without P_rect_02/P2, a focal length outside
// (0, 1e5) px or a principal point outside the frame. A calibration file whose S_rect_02 differs from
// the frames is scaled to them (frames resized from KITTI's), with a warning.
// With `learned` (model.learn_intrinsics) and no camera given, a nominal 90-degree camera: the
// networks replace it with the one they learn.
torch::Tensor clip_camera(const CameraConfig& camera, int64_t width, int64_t height, const std::string& clip,
                          bool learned = false);

// Short text for logs: "fx 721.5 fy 721.5 cx 609.6 cy 172.9 at 1242x375".
std::string describe_camera(const torch::Tensor& K, int64_t width, int64_t height);

}  // namespace geo
