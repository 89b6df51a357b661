// Test-time refinement (Struct2Depth's online refinement, Casser et al. 2019): a trained model
// trained on, for a few iterations, on the very clip it is then asked about. For short or hard clips
// (stop-and-go traffic, a scene unlike the training data) the networks adapt to the clip's camera,
// scene and motion without labels; geo_infer --refine N.
//
// The clip trains as configs/video.yaml trains footage (minimum reprojection, auto-masking, frames
// where the camera stands left out, its batch), with the model's own architecture and size, on every
// frame (no validation block), the whole frame resized as geo_infer sees it (no crop), at half
// video.yaml's learning rate and with BatchNorm's statistics kept (a few frames' batch statistics
// would replace what the model measured on many: on the real KITTI runs that alone cost 10% AbsRel
// and made refinement unstable), its depth held to the model's own (weights.anchor 1: a few frames
// of traffic otherwise teach depth that follows texture). Depth and pose train; a FlowNet the model
// has is kept as it was.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace geo {

// Depth held to the source model's (losses/depth_anchor.h) by default: on the real KITTI traffic
// frames 50 iterations without it raised AbsRel from 0.347 to 0.369; at 1 it stays at 0.345
// (docs/video.md).
inline constexpr double kRefineAnchor = 1.0;

struct RefineOptions {
  std::string checkpoint;         // training checkpoint, run folder or geo_export model file
  std::string input;              // the clip: a video file or a folder of frames
  int64_t iterations = 0;         // training iterations on the clip (>= 1)
  double anchor = kRefineAnchor;  // the stage's weights.anchor
  // fx fy cx cy in pixels of the clip's frames (unused for a model that learns its camera: its
  // camera head trains on).
  std::vector<double> intrinsics;
  std::string run_dir;  // the refinement's run folder (created; must not hold a run)
  std::string device = "auto";
  int threads = 0;                  // intra-op threads (0: all cores)
  std::string option = "--refine";  // names the setting in messages
};

// Trains, then writes the refined networks as a model file <run_dir>/refined.pt (the FlowNet, when
// the source has one, unchanged) and returns its path. Returns "" when a signal stopped the
// training (its checkpoint is in run_dir). Throws std::runtime_error naming the value at fault: fewer
// than 1 iteration, a clip without motion to learn from, a source that is not a geo model.
std::string refine(const RefineOptions& options);

}  // namespace geo
