// The one rule for a camera given to geo in pixels, used wherever a camera comes in.
#pragma once

#include <cstdint>
#include <string>

namespace geo {

// The rule for every camera given to geo (data.camera and calibration files for geo_train and
// geo_eval, geo_infer --intrinsics, the library's and Python's intrinsics): focal lengths in
// pixels, finite, >= 1 and < 1e5 (KITTI: ~720; normalised intrinsics, fx ~ 0.6, are the mistake this
// catches; 1e5 px is 0.4 degrees of view); the principal point inside the width x height frame it
// belongs to ([0, width] x [0, height]), or, where no frame size is known (a calibration file),
// within 1e5 pixels. Returns "" for a plausible camera, else what is wrong, naming the values.
std::string camera_problem(double fx, double fy, double cx, double cy, int64_t width = 0, int64_t height = 0);

}  // namespace geo
