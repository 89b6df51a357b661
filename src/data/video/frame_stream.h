// One clip's frames in order, decoded one at a time: a single image, a folder of frames (any names,
// natural order) or a video (anything OpenCV's FFmpeg back-end reads). Training (video_clips.h) and
// geo_infer read clips through it. Needs OpenCV.
#pragma once

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>
#include <torch/torch.h>

#include <cstdint>
#include <string>
#include <vector>

namespace geo {

// True for the image files a frame folder is made of: png, jpg, jpeg, bmp, tif, tiff, webp (any case).
bool is_image_name(const std::string& path);

// The image files of a frame folder in natural order (frame2 before frame10). A link named like an
// image that leads nowhere throws, naming it.
std::vector<std::string> frame_files(const std::string& folder);

class FrameStream {
 public:
  // Opens `path`: an image file, a folder of them or a video. Errors are std::runtime_errors that
  // begin "<label> '<path>': " (label: what the user called it, e.g. "clip" or "--input"): it does not
  // exist, is a folder without images, is neither an image nor a readable video; later an
  // unreadable image or a frame of another size.
  FrameStream(const std::string& path, const std::string& label);

  // The next frame: its name (an image's file name without extension; a video frame's number,
  // 000042) and, with `bgr`, its pixels (BGR as OpenCV decodes it: a file's own depth and channels,
  // see mat_to_tensor; a video's 8-bit); false after the last. With `bgr` null a
  // folder's file is passed over unread (a video's frame is decoded all the same). A frame whose
  // size differs from the first's throws, naming both; so does a video frame that cannot be
  // decoded while later ones can, or a video that ends before the frame count its file states.
  bool next(std::string& name, cv::Mat* bgr);

  const std::string& path() const { return path_; }
  bool is_video() const { return video_; }
  const std::vector<std::string>& files() const { return files_; }  // an image's or a folder's; none for a video
  int64_t index() const { return index_; }  // of the frame last returned, from 0; -1 before the first
  double fps() const { return fps_; }       // a video's own rate; 0 when unknown (images)
  int64_t width() const { return width_; }  // the first frame's size; 0 before it is read
  int64_t height() const { return height_; }

 private:
  void check_size(const cv::Mat& m, const std::string& what);
  void check_video_end();

  std::string path_, where_, first_;
  bool video_ = false;
  std::vector<std::string> files_;
  cv::VideoCapture capture_;
  double fps_ = 0;
  int64_t index_ = -1, width_ = 0, height_ = 0;
  int64_t frame_count_ = 0;  // a video's, as its file states it; 0 when unknown
};

// The first `count` frames of an image, frame folder or video (fewer when it has fewer), each
// resized to height x width (resized_mat_to_frame: uint8 RGB [3,H,W] for 8-bit input): calibration
// frames (int8). Errors as FrameStream's, labelled `label`.
std::vector<torch::Tensor> first_frames(const std::string& path, int64_t count, int64_t height, int64_t width,
                                        const std::string& label);

}  // namespace geo
