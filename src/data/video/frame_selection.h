// Which frames of a clip teach (data.video): frame-rate subsampling (KITTI is 10 fps; a 30 or 60 fps
// clip has too little parallax between neighbours), static frames left out (GeoNet's static-frame
// list does so for KITTI; here detected from the images), and validation as whole time blocks that
// never neighbour a training frame. LibTorch only: the decoding is in video_clips.h.
#pragma once

#include <torch/torch.h>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace geo {

// Every stride-th decoded frame gives source_fps / target_fps: round(source / target), at least 1;
// 1 when either rate is unknown (0).
int64_t frame_rate_stride(double source_fps, double target_fps);

// A small blurred grey image of a frame for motion tests: [3,H,W] in [0,1] -> [h,w] float32 with h
// about 32 rows (area average, which also removes pixel noise).
torch::Tensor motion_thumbnail(const torch::Tensor& rgb);

// Pixels of two thumbnails that changed by more than this (4/255): sensor noise and compression
// stay below it, texture moving by a pixel does not.
constexpr double kChangedLevel = 4.0 / 255.0;
// The fraction of pixels of two thumbnails that differ by more than kChangedLevel, in [0, 1].
double changed_fraction(const torch::Tensor& a, const torch::Tensor& b);

// Decides frame by frame, in decoding order, which frames are kept: every `stride`-th frame is looked
// at, and kept unless less than `static_threshold` of its pixels changed since the last kept frame
// or, where enough changed, the camera stood while other things moved (`camera_moved`, for example
// camera_motion.h's test against the last kept frame). So after a stop the next kept frame is the
// next one where the camera moved, as GeoNet's static-frame removal.
class FrameSelector {
 public:
  FrameSelector(int64_t stride, double static_threshold);
  // Frame `index` (decoding order, from 0) with its thumbnail (undefined for frames skipped by the
  // rate: wants() says whether one is needed). `camera_moved`, where given, is asked when enough
  // pixels changed: whether the camera moved since the last kept frame. True when the frame is kept.
  bool wants(int64_t index) const { return index % stride_ == 0; }
  bool offer(int64_t index, const torch::Tensor& thumbnail, const std::function<bool()>& camera_moved = {});

  const std::vector<int64_t>& kept() const { return kept_; }
  int64_t decoded() const { return decoded_; }
  int64_t looked_at() const { return decoded_ - by_rate_; }
  int64_t skipped_by_rate() const { return by_rate_; }
  int64_t skipped_static() const { return static_; }         // under static_threshold of the pixels changed
  int64_t skipped_standing() const { return standing_; }     // pixels changed, the camera stood
  double largest_change() const { return largest_change_; }  // over the frames looked at
  // The share of the frames looked at after the first where the camera had moved since the last
  // kept frame (1 when only one was looked at).
  double moving_share() const;

 private:
  int64_t stride_;
  double threshold_;
  torch::Tensor last_kept_;
  std::vector<int64_t> kept_;
  int64_t decoded_ = 0, by_rate_ = 0, static_ = 0, standing_ = 0;
  double largest_change_ = 0;
};

// The camera moved in fewer than this share of a clip's frames: it is unlikely to teach depth.
constexpr double kFewMovingFrames = 1.0 / 3.0;

// Kept frames 0..n-1 of one clip split into contiguous runs: validation blocks of at most
// `val_block` frames, val_fraction of the clip in all, spread over it (block j ends at (j+1)/B of the
// clip); training the rest. seq_length/2 frames on the training side of every block edge are left
// out, so no training snippet reaches within seq_length/2 frames of a validation frame. A clip too
// short for one validation snippet gives no validation block.
struct ClipRuns {
  std::vector<std::vector<int64_t>> train, val;  // positions 0..n-1, each run in order
  int64_t edge_dropped = 0;                      // frames left out at block edges
};
ClipRuns split_clip(int64_t n, double val_fraction, int64_t val_block, int64_t seq_length);

// Targets of seq_length-frame snippets inside each run (positions whose seq_length/2 neighbours on
// both sides are in the run): (run index, position in run).
std::vector<std::pair<size_t, int64_t>> snippet_targets(const std::vector<std::vector<int64_t>>& runs,
                                                        int64_t seq_length);

// Natural order of file names: digit runs compare as numbers ("frame2" < "frame10"), the rest as text.
bool natural_less(const std::string& a, const std::string& b);

}  // namespace geo
