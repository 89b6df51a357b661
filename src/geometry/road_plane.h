// Metric scale from the camera's height above the road. A monocular depth map is right up to one
// unknown factor; the road in front of the car is a plane whose distance from the camera the car
// knows (KITTI: 1.65 m). Fitting that plane to the predicted depth gives the factor:
//   scale = known height / fitted height.
// Assumptions: the lower part of the image sees a flat road near the car, the camera's y axis points
// down (KITTI, geo_synth), the intrinsics are those of the depth map's size. It fails (found = false,
// with the reason) where no such plane is seen: a car or a wall filling the lower image, a steep
// slope, a depth map with too few valid pixels.
#pragma once

#include <torch/torch.h>

#include <cstdint>
#include <string>
#include <vector>

namespace geo {

struct RoadPlaneOptions {
  // A level camera (KITTI's are mounted within about a degree of level, as geo_synth's): the road's
  // normal is the camera's y axis and only the height is fitted. Off: the normal is fitted too
  // (a pitched camera), which a predicted depth map's bent near field can tilt.
  bool level_camera = true;
  double bottom_fraction = 0.4;      // rows used: the lowest 40% of the image (the road ahead)
  double max_tilt_deg = 20.0;        // the plane's normal within this angle of the camera's down axis
  double inlier_band = 0.05;         // inliers lie within this fraction of the plane's height of it
  double min_inlier_fraction = 0.2;  // of the candidate points, or no plane is found
  int iterations = 300;              // RANSAC samples of three points
  int64_t max_points = 20000;        // candidate points, evenly subsampled
  uint64_t seed = 1;                 // the samples are drawn from this seed (a fit is reproducible)
};

struct RoadPlane {
  bool found = false;
  double height = 0;             // the camera's distance from the plane, in the depth map's unit
  double normal[3] = {0, 0, 0};  // unit normal, camera coordinates, pointing down (towards the road)
  int64_t inliers = 0, points = 0;
  std::string why;  // when !found: what was missing
};

// The points of the image's lower part, back-projected. Level camera: RANSAC over single points for
// the height h (the points within inlier_band x h of y = h count), refined by the inliers' mean,
// twice. Otherwise RANSAC over triples (planes tilted more than max_tilt_deg from horizontal are
// skipped), refined by least squares (the smallest principal axis of the inliers), twice. The
// "RANSAC + least squares" ground-plane estimate of monocular visual odometry (Kitt et al., IV 2011,
// with a known camera pitch; Song & Chandraker, CVPR 2014; Zhou et al., "Reliable scale estimation
// and correction for monocular visual odometry", IV 2016).
// depth: [H,W] (or [1,H,W]); pixels <= 0 or non-finite are ignored. K: [3,3] for that size.
RoadPlane fit_road_plane(const torch::Tensor& depth, const torch::Tensor& K, const RoadPlaneOptions& options = {});

// The factor that takes a depth map (or its camera motion) to metres: known_height / plane.height;
// 0 when the plane was not found.
double camera_height_scale(const RoadPlane& plane, double known_height);

// Smoothed per-frame scales over a sequence: the median of the found scales in a window of
// `radius` frames on each side (frames whose plane was not found take their neighbours'); 0 where
// no frame of the window has one.
std::vector<double> smooth_scales(const std::vector<double>& scales, int radius = 5);

}  // namespace geo
