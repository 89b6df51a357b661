// What geo_infer shows a user besides per-frame images: videos of colour-mapped outputs and a top
// view of the camera's trajectory. OpenCV.
#pragma once

#include <torch/torch.h>

#include <memory>
#include <string>

namespace geo {

// A Motion-JPEG AVI (readable by every player and by OpenCV without extra codecs), written to
// `<path>.tmp.avi` and moved to `path` by close(): a failed or interrupted run never leaves a
// truncated file under the final name. Frames are RGB [3,H,W] float in [0,1] or uint8; every frame
// must have the first one's size.
class VideoWriter {
 public:
  VideoWriter(std::string path, double fps);
  ~VideoWriter();  // without close(): the partial file is removed
  VideoWriter(const VideoWriter&) = delete;
  VideoWriter& operator=(const VideoWriter&) = delete;
  void write(const torch::Tensor& rgb);
  void close();
  int64_t frames() const { return frames_; }
  const std::string& path() const { return path_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  std::string path_;
  double fps_;
  int64_t frames_ = 0;
};

// Top view (x right, z forward = up) of camera-to-world poses [N,4,4] (KITTI pose files), the
// estimate in orange and, when given, the ground truth [M,4,4] in black, both fitted into a
// size x size image with equal scales on both axes, a 10-step grid labelled in the poses' units and
// the start marked. -> RGB [3,size,size] float in [0,1].
torch::Tensor trajectory_plot(const torch::Tensor& poses, const torch::Tensor& truth = {}, int size = 640);

}  // namespace geo
