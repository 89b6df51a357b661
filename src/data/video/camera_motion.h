// Whether the camera moved between two frames, told by the motion of the static world rather than by
// how many pixels changed: in stop-and-go traffic a truck passing a standing camera changes most of
// the pixels while the camera teaches nothing.
//
// Features are tracked from one frame to the other (Shi-Tomasi corners, pyramidal Lucas-Kanade,
// kept where tracking back lands within a quarter pixel), then the largest set of them that a
// rotation of the camera alone explains (x_b = K R K^-1 x_a, found by RANSAC, within
// `parallax_px` at a width of kMotionWidth) is the static world seen by a camera that did not move: a camera that translated
// gives the static world parallax, which no rotation explains. The camera stands when that set
// holds most points in more than `still_share` of the image (a 4x3 grid of cells, each voting by its
// points, so that a textured truck or the car ahead does not outvote the road and the buildings;
// things moving in front of a standing camera are the rest). Needs OpenCV.
#pragma once

#include <opencv2/core.hpp>
#include <torch/torch.h>

#include <cstdint>

namespace geo {

// The width the parallax threshold is given at (KITTI's training width): on images of another width
// it scales with it, so that the test does not depend on the resolution it runs at.
constexpr int64_t kMotionWidth = 416;

struct CameraMotionOptions {
  double parallax_px = 0.5;  // pixels at kMotionWidth: less is no translation
  double still_share = 0.5;  // the camera stands when a rotation explains more than this share of the image
};

struct CameraMotion {
  int64_t tracked = 0;     // features tracked both ways
  double still_share = 0;  // the share of the image (cells with tracked points) a rotation alone explains
  bool moved = true;       // false: the camera stood (or only turned); true also when too few tracked
};

// Fewer tracked features than this and the frames cannot tell: the camera counts as moved.
constexpr int64_t kMinTrackedFeatures = 12;

// a, b: 8-bit grey images of one size; K: [3,3] intrinsics at that size (a nominal one will do: the
// rotation's image motion depends on it only weakly).
CameraMotion camera_motion(const cv::Mat& a, const cv::Mat& b, const torch::Tensor& K,
                           const CameraMotionOptions& options);

// The test a clip's frames take in decoding order (FrameSelector's camera_moved): the camera moved
// before a frame when it moved since the last kept frame (slow creeping adds up) or since the frame
// looked at just before (a start after a long stop, when much else changed since the last kept one).
class StandingCameraTest {
 public:
  StandingCameraTest(torch::Tensor K, CameraMotionOptions options);
  // Whether the camera moved before `grey` (camera_motion's image); true for the first frame.
  bool moved(const cv::Mat& grey);
  // Every frame looked at, after the verdict, in order: `kept` whether the frame was kept.
  void looked_at(const cv::Mat& grey, bool kept);

 private:
  torch::Tensor K_;
  CameraMotionOptions options_;
  cv::Mat last_kept_, previous_;
  bool previous_is_kept_ = false;
};

// An image as camera_motion takes it, 8-bit grey: from RGB [3,H,W] in [0,1] (float) or 0..255 (uint8),
// or from a decoded image (grey, BGR or BGRA; 8 or 16 bits).
cv::Mat motion_grey(const torch::Tensor& rgb);
cv::Mat motion_grey(const cv::Mat& decoded);

}  // namespace geo
