#include "data/visual_outputs.h"

#include "core/tensor_checks.h"
#include "data/cv_tensor.h"

#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <system_error>

namespace geo {

struct VideoWriter::Impl {
  cv::VideoWriter writer;
  cv::Size size;
  std::string tmp;
};

VideoWriter::VideoWriter(std::string path, double fps)
    : impl_(std::make_unique<Impl>()), path_(std::move(path)), fps_(fps) {
  if (!(fps > 0))
    throw std::runtime_error("video '" + path_ + "': frame rate must be positive, got " + std::to_string(fps));
  impl_->tmp = path_ + ".tmp.avi";
}

VideoWriter::~VideoWriter() {
  if (!impl_) return;
  impl_->writer.release();
  std::error_code ec;
  std::filesystem::remove(impl_->tmp, ec);
}

void VideoWriter::write(const torch::Tensor& rgb) {
  if (!impl_) throw std::runtime_error("video '" + path_ + "' is already closed");
  const cv::Mat bgr = tensor_to_bgr8(rgb);
  if (!impl_->writer.isOpened()) {
    impl_->size = bgr.size();
    impl_->writer.open(impl_->tmp, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), fps_, impl_->size);
    if (!impl_->writer.isOpened()) throw std::runtime_error("cannot write video '" + path_ + "' (Motion-JPEG AVI)");
  } else if (bgr.size() != impl_->size) {
    throw std::runtime_error("video '" + path_ + "': frame " + std::to_string(frames_) + " is " +
                             std::to_string(bgr.cols) + "x" + std::to_string(bgr.rows) + " but the first was " +
                             std::to_string(impl_->size.width) + "x" + std::to_string(impl_->size.height));
  }
  impl_->writer.write(bgr);
  ++frames_;
}

void VideoWriter::close() {
  if (!impl_) return;
  if (frames_ == 0) throw std::runtime_error("video '" + path_ + "': no frames to write");
  impl_->writer.release();
  std::filesystem::rename(impl_->tmp, path_);
  impl_.reset();
}

namespace {

// Camera centres on the ground plane: (x, z) of each pose's translation -> [N,2] float64.
torch::Tensor top_view(const torch::Tensor& poses, const char* what) {
  check_shape(poses, what, {-1, 4, 4});
  return poses.detach()
      .to(torch::kCPU, torch::kFloat64)
      .select(2, 3)
      .index({torch::indexing::Slice(), torch::tensor({0, 2})});
}

double nice_step(double span) {  // 1, 2 or 5 x 10^k, about a tenth of the span
  const double raw = std::max(span, 1e-9) / 10, p = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0})
    if (m * p >= raw) return m * p;
  return 10 * p;
}

}  // namespace

torch::Tensor trajectory_plot(const torch::Tensor& poses, const torch::Tensor& truth, int size) {
  if (size < 64) throw std::runtime_error("trajectory_plot: size must be at least 64, got " + std::to_string(size));
  std::vector<torch::Tensor> tracks{top_view(poses, "poses")};
  if (truth.defined()) tracks.push_back(top_view(truth, "ground-truth poses"));
  const auto all = torch::cat(tracks, 0);
  const auto lo = std::get<0>(all.min(0)), hi = std::get<0>(all.max(0));
  const double x0 = lo[0].item<double>(), z0 = lo[1].item<double>();
  const double span = std::max({hi[0].item<double>() - x0, hi[1].item<double>() - z0, 1e-6});
  const double margin = 0.08 * size, scale = (size - 2 * margin) / span;
  // Centre the smaller extent.
  const double ox = margin + 0.5 * ((size - 2 * margin) - (hi[0].item<double>() - x0) * scale);
  const double oz = margin + 0.5 * ((size - 2 * margin) - (hi[1].item<double>() - z0) * scale);
  auto to_px = [&](double x, double z) {
    return cv::Point(static_cast<int>(std::lround(ox + (x - x0) * scale)),
                     static_cast<int>(std::lround(size - (oz + (z - z0) * scale))));
  };
  cv::Mat img(size, size, CV_8UC3, cv::Scalar(255, 255, 255));
  const double step = nice_step(span);
  const cv::Scalar grid(225, 225, 225);
  for (double g = std::floor(x0 / step) * step; g <= x0 + span + step; g += step)
    cv::line(img, to_px(g, z0 - span), to_px(g, z0 + 2 * span), grid, 1);
  for (double g = std::floor(z0 / step) * step; g <= z0 + span + step; g += step)
    cv::line(img, to_px(x0 - span, g), to_px(x0 + 2 * span, g), grid, 1);
  char label[64];
  std::snprintf(label, sizeof label, "grid %g (x right, z forward)", step);
  cv::putText(img, label, cv::Point(8, size - 8), cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(90, 90, 90), 1,
              cv::LINE_AA);
  const cv::Scalar colours[2] = {cv::Scalar(0, 120, 255), cv::Scalar(0, 0, 0)};  // BGR: orange estimate, black truth
  const char* names[2] = {"estimate", "ground truth"};
  for (size_t t = tracks.size(); t-- > 0;) {  // the truth first, the estimate on top
    const auto a = tracks[t].contiguous();
    const double* v = a.data_ptr<double>();
    std::vector<cv::Point> pts;
    for (int64_t i = 0; i < a.size(0); ++i) pts.push_back(to_px(v[2 * i], v[2 * i + 1]));
    if (pts.size() > 1) cv::polylines(img, pts, false, colours[t], 2, cv::LINE_AA);
    if (!pts.empty()) cv::circle(img, pts.front(), 4, colours[t], cv::FILLED, cv::LINE_AA);
    cv::putText(img, names[t], cv::Point(8, 18 + 16 * static_cast<int>(t)), cv::FONT_HERSHEY_SIMPLEX, 0.45, colours[t],
                1, cv::LINE_AA);
  }
  cv::Mat rgb;
  cv::cvtColor(img, rgb, cv::COLOR_BGR2RGB);
  return torch::from_blob(rgb.data, {size, size, 3}, torch::kUInt8)
      .permute({2, 0, 1})
      .to(torch::kFloat32)
      .div(255)
      .contiguous();
}

}  // namespace geo
