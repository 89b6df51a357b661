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
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
  for (const char* e : {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp"})
    if (ext == e) return true;
  return false;
}

std::vector<std::string> frame_files(const std::string& folder) {
  std::vector<std::string> files;
  for (const auto& e : fs::directory_iterator(folder))
    if (e.is_regular_file() && is_image_name(e.path().string())) files.push_back(e.path().string());
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
    throw std::runtime_error(where_ + "OpenCV cannot open it as a video (not a video, or a codec this OpenCV "
                             "lacks); a folder of its frames works too");
  const double fps = capture_.get(cv::CAP_PROP_FPS);
  if (std::isfinite(fps) && fps > 0 && fps < 1000) fps_ = fps;
}

void FrameStream::check_size(const cv::Mat& m, const std::string& what) {
  if (first_.empty()) {
    first_ = what;
    width_ = m.cols;
    height_ = m.rows;
  } else if (m.cols != width_ || m.rows != height_) {
    throw std::runtime_error(where_ + what + " is " + std::to_string(m.cols) + "x" + std::to_string(m.rows) + " but " + first_ +
                             " is " + std::to_string(width_) + "x" + std::to_string(height_) +
                             ": the frames of one clip must have one size");
  }
}

bool FrameStream::next(std::string& name, cv::Mat* bgr) {
  if (video_) {
    cv::Mat m;
    if (!capture_.read(m) || m.empty()) return false;
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
    if (m.empty()) throw std::runtime_error(where_ + "cannot read image '" + file + "' (missing, empty or not an image)");
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
