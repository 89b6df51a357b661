#include "data/video/frame_stream.h"

#include "data/cv_tensor.h"
#include "data/video/frame_selection.h"

#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <stdexcept>

namespace fs = std::filesystem;

namespace geo {

bool is_image_name(const std::string& path) {
  auto ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
  for (const char* e : {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp"})
    if (ext == e) return true;
  return false;
}

std::vector<std::string> frame_files(const std::string& folder) {
  std::vector<std::string> files;
  for (const auto& e : fs::directory_iterator(folder)) {
    if (!is_image_name(e.path().string())) continue;
    if (e.is_regular_file()) {
      files.push_back(e.path().string());
    } else if (e.is_symlink() && !fs::exists(e.status())) {
      // Passing over it would silently drop a frame from the middle of the sequence.
      throw std::runtime_error("frame '" + e.path().string() + "' in '" + folder + "' is a link to nothing ('" +
                               fs::read_symlink(e.path()).string() + "' does not exist): restore or remove it");
    }
  }
  std::sort(files.begin(), files.end(), [](const std::string& a, const std::string& b) {
    return natural_less(fs::path(a).filename().string(), fs::path(b).filename().string());
  });
  return files;
}

FrameStream::FrameStream(const std::string& path, const std::string& label)
    : path_(path), where_(label + " '" + path + "': ") {
  if (fs::is_directory(path)) {
    files_ = frame_files(path);
    if (files_.empty())
      throw std::runtime_error(where_ + "the folder holds no image files (png, jpg, jpeg, bmp, tif, webp)");
    return;
  }
  if (!fs::exists(path)) throw std::runtime_error(where_ + "does not exist");
  if (is_image_name(path)) {
    files_ = {path};
    return;
  }
  // OpenCV's FFmpeg back-end (Debian's OpenCV has it); the GStreamer one prints pages of errors for
  // a file it cannot read.
  video_ = true;
  capture_.open(path, cv::CAP_FFMPEG);
  if (!capture_.isOpened())
    throw std::runtime_error(where_ +
                             "OpenCV cannot open it as a video (not a video, or a codec this OpenCV "
                             "lacks); a folder of its frames works too");
  const double fps = capture_.get(cv::CAP_PROP_FPS);
  if (std::isfinite(fps) && fps > 0 && fps < 1000) fps_ = fps;
  const double count = capture_.get(cv::CAP_PROP_FRAME_COUNT);
  if (std::isfinite(count) && count > 0 && count < 1e9) frame_count_ = static_cast<int64_t>(count);
}

// A video that stops decoding before its end: a frame that cannot be decoded in the middle (later
// ones decode) or a file cut short. Both refuse the clip: a sequence with frames missing from its
// middle would teach motions that never happened. The container's frame count may be off by one.
void FrameStream::check_video_end() {
  const int64_t decoded = index_ + 1;
  int64_t later = 0;
  for (int i = 0; i < 8; ++i)
    if (capture_.grab()) ++later;
  if (later > 0)
    throw std::runtime_error(where_ + "frame " + std::to_string(decoded + 1) +
                             (frame_count_ > 0 ? " of " + std::to_string(frame_count_) : "") +
                             " cannot be decoded while later ones can (a damaged file): re-encode or cut the video "
                             "(for example ffmpeg -i IN -c:v mjpeg -q:v 2 OUT.avi), or give a folder of its frames");
  if (frame_count_ > 0 && decoded + 1 < frame_count_)
    throw std::runtime_error(where_ + "only " + std::to_string(decoded) + " of its " + std::to_string(frame_count_) +
                             " frames can be decoded (a damaged or cut file): re-encode or cut the video, or give a "
                             "folder of its frames");
}

void FrameStream::check_size(const cv::Mat& m, const std::string& what) {
  if (first_.empty()) {
    first_ = what;
    width_ = m.cols;
    height_ = m.rows;
  } else if (m.cols != width_ || m.rows != height_) {
    throw std::runtime_error(where_ + what + " is " + std::to_string(m.cols) + "x" + std::to_string(m.rows) + " but " +
                             first_ + " is " + std::to_string(width_) + "x" + std::to_string(height_) +
                             ": the frames of one clip must have one size");
  }
}

bool FrameStream::next(std::string& name, cv::Mat* bgr) {
  if (video_) {
    cv::Mat m;
    if (!capture_.read(m) || m.empty()) {
      check_video_end();
      return false;
    }
    ++index_;
    char buf[32];
    std::snprintf(buf, sizeof buf, "%06lld", static_cast<long long>(index_));
    name = buf;
    check_size(m, "frame " + std::to_string(index_));
    if (bgr) *bgr = m;
    return true;
  }
  if (index_ + 1 >= static_cast<int64_t>(files_.size())) return false;
  const std::string& file = files_[static_cast<size_t>(++index_)];
  name = fs::path(file).stem().string();
  if (bgr) {
    cv::Mat m = cv::imread(file, cv::IMREAD_UNCHANGED);  // 16-bit and grey images as they are (mat_to_tensor)
    if (m.empty())
      throw std::runtime_error(where_ + "cannot read image '" + file + "' (missing, empty or not an image)");
    check_size(m, "'" + file + "'");
    *bgr = m;
  }
  return true;
}

std::vector<torch::Tensor> first_frames(const std::string& path, int64_t count, int64_t height, int64_t width,
                                        const std::string& label) {
  FrameStream stream(path, label);
  std::vector<torch::Tensor> frames;
  std::string name;
  cv::Mat m;
  while (static_cast<int64_t>(frames.size()) < count && stream.next(name, &m))
    frames.push_back(resized_mat_to_frame(m, height, width, path + " [" + name + "]"));
  return frames;
}

}  // namespace geo
