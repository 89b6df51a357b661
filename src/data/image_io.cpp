#include "data/image_io.h"
#include "data/cv_tensor.h"

#include "core/files.h"
#include "core/tensor_checks.h"

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cmath>
#include <filesystem>
#include <stdexcept>

namespace geo {
namespace {

cv::Mat read_raw(const std::string& path, int flags) {
  if (!std::filesystem::exists(path)) throw std::runtime_error("image not found: '" + path + "'");
  cv::Mat m;
  try {
    m = cv::imread(path, flags);
  } catch (const cv::Exception& e) {  // e.g. a header claiming more pixels than OpenCV accepts
    throw std::runtime_error("cannot decode image '" + path + "': " + e.err +
                             " (corrupt, or larger than OpenCV reads)");
  }
  if (m.empty()) throw std::runtime_error("cannot decode image '" + path + "' (corrupt or not an image)");
  return m;
}

// Encodes in memory, then writes atomically (a crash never leaves half a PNG).
std::string encode(const cv::Mat& m, const std::string& ext, const std::string& what) {
  std::vector<uchar> buf;
  if (!cv::imencode(ext, m, buf)) throw std::runtime_error(what + ": cannot encode image");
  return std::string(buf.begin(), buf.end());
}

void write_raw(const std::string& path, const cv::Mat& m) {
  const auto dot = path.rfind('.');
  const std::string ext = dot == std::string::npos ? ".png" : path.substr(dot);
  const std::string bytes = encode(m, ext, path);
  std::filesystem::create_directories(
      std::filesystem::path(path).parent_path().empty() ? "." : std::filesystem::path(path).parent_path());
  write_file_atomic(path, bytes);
}

}  // namespace

namespace {

// 1-, 3- or 4-channel BGR(A) -> RGB in a new buffer (the caller's image stays BGR).
cv::Mat to_rgb(const cv::Mat& bgr_any, const std::string& path) {
  cv::Mat m;
  if (bgr_any.channels() == 1) cv::cvtColor(bgr_any, m, cv::COLOR_GRAY2RGB);
  else if (bgr_any.channels() == 3) cv::cvtColor(bgr_any, m, cv::COLOR_BGR2RGB);
  else if (bgr_any.channels() == 4) cv::cvtColor(bgr_any, m, cv::COLOR_BGRA2RGB);
  else
    throw std::runtime_error("image '" + path + "' has " + std::to_string(bgr_any.channels()) +
                             " channels; expected 1, 3 or 4");
  return m;
}

// The image at height x width: INTER_AREA when shrinking both sides, linear otherwise; as it is at that size.
cv::Mat resized(const cv::Mat& image, int64_t height, int64_t width) {
  if (image.rows == height && image.cols == width) return image;
  const bool shrink = height < image.rows && width < image.cols;
  cv::Mat r;
  cv::resize(image, r, cv::Size(static_cast<int>(width), static_cast<int>(height)), 0, 0,
             shrink ? cv::INTER_AREA : cv::INTER_LINEAR);
  return r;
}

}  // namespace

torch::Tensor mat_to_tensor(const cv::Mat& bgr_any, const std::string& path) {
  const cv::Mat m = to_rgb(bgr_any, path);
  cv::Mat f;
  m.convertTo(f, CV_32FC3, m.depth() == CV_16U ? 1.0 / 65535.0 : 1.0 / 255.0);
  // A copy in any case (f's buffer is gone on return; contiguous() would not copy a 1x1 image).
  return torch::from_blob(f.data, {f.rows, f.cols, 3}, torch::kFloat32)
      .permute({2, 0, 1})
      .clone(at::MemoryFormat::Contiguous);
}

cv::Mat tensor_to_bgr8(const torch::Tensor& image) {
  check_shape(image, "image", {3, -1, -1});
  auto t = image.detach().to(torch::kCPU);
  if (t.scalar_type() != torch::kUInt8) t = (t.to(torch::kFloat32).clamp(0, 1) * 255).round().to(torch::kUInt8);
  t = t.permute({1, 2, 0}).contiguous();
  cv::Mat rgb(static_cast<int>(t.size(0)), static_cast<int>(t.size(1)), CV_8UC3, t.data_ptr<uint8_t>());
  cv::Mat bgr;
  cv::cvtColor(rgb, bgr, cv::COLOR_RGB2BGR);
  return bgr;
}

torch::Tensor read_image(const std::string& path) { return mat_to_tensor(read_raw(path, cv::IMREAD_UNCHANGED), path); }

torch::Tensor read_image_resized(const std::string& path, int64_t height, int64_t width, int64_t* original_height,
                                 int64_t* original_width) {
  const cv::Mat m = read_raw(path, cv::IMREAD_UNCHANGED);
  if (original_height) *original_height = m.rows;
  if (original_width) *original_width = m.cols;
  return resized_mat_to_tensor(m, height, width, path);
}

torch::Tensor resized_mat_to_tensor(const cv::Mat& bgr_any, int64_t height, int64_t width, const std::string& path) {
  return mat_to_tensor(resized(bgr_any, height, width), path);
}

torch::Tensor resized_mat_to_frame(const cv::Mat& bgr_any, int64_t height, int64_t width, const std::string& path) {
  if (bgr_any.depth() != CV_8U) return resized_mat_to_tensor(bgr_any, height, width, path);
  const cv::Mat m = to_rgb(resized(bgr_any, height, width), path);
  return torch::from_blob(m.data, {m.rows, m.cols, 3}, torch::kUInt8)
      .permute({2, 0, 1})
      .clone(at::MemoryFormat::Contiguous);
}

void write_image(const std::string& path, const torch::Tensor& image) { write_raw(path, tensor_to_bgr8(image)); }

std::string encode_png(const torch::Tensor& image) { return encode(tensor_to_bgr8(image), ".png", "PNG"); }

// "8-bit", "16-bit", "32-bit float", ...: what an image's pixels are, for error messages.
static std::string pixel_depth_name(int depth) {
  switch (depth) {
    case CV_8U:
      return "8-bit";
    case CV_8S:
      return "8-bit signed";
    case CV_16U:
      return "16-bit";
    case CV_16S:
      return "16-bit signed";
    case CV_32S:
      return "32-bit integer";
    case CV_32F:
      return "32-bit float";
    case CV_64F:
      return "64-bit float";
    default:
      return "depth " + std::to_string(depth);
  }
}

FlowMap read_flow_png(const std::string& path) {
  cv::Mat m = read_raw(path, cv::IMREAD_UNCHANGED);
  if (m.depth() != CV_16U || m.channels() != 3)
    throw std::runtime_error("flow PNG '" + path + "' must be 16-bit with 3 channels (KITTI flow format), got " +
                             std::to_string(m.channels()) + " channel(s) of " + pixel_depth_name(m.depth()));
  FlowMap out;
  out.flow = torch::empty({2, m.rows, m.cols}, torch::kFloat32);
  out.valid = torch::empty({1, m.rows, m.cols}, torch::kFloat32);
  auto f = out.flow.accessor<float, 3>();
  auto v = out.valid.accessor<float, 3>();
  for (int y = 0; y < m.rows; ++y) {
    const auto* row = m.ptr<cv::Vec3w>(y);
    for (int x = 0; x < m.cols; ++x) {
      // OpenCV order is BGR: [0] = valid, [1] = v, [2] = u.
      const bool ok = row[x][0] > 0;
      v[0][y][x] = ok ? 1.f : 0.f;
      f[0][y][x] = ok ? (static_cast<float>(row[x][2]) - 32768.f) / 64.f : 0.f;
      f[1][y][x] = ok ? (static_cast<float>(row[x][1]) - 32768.f) / 64.f : 0.f;
    }
  }
  return out;
}

void write_flow_png(const std::string& path, const torch::Tensor& flow, const torch::Tensor& valid) {
  check_shape(flow, "flow", {2, -1, -1});
  auto fl = flow.detach().to(torch::kCPU, torch::kFloat32).contiguous();
  auto va = valid.defined()
                ? valid.detach().to(torch::kCPU, torch::kFloat32).reshape({fl.size(1), fl.size(2)}).contiguous()
                : torch::ones({fl.size(1), fl.size(2)});
  auto f = fl.accessor<float, 3>();
  auto v = va.accessor<float, 2>();
  cv::Mat m(static_cast<int>(fl.size(1)), static_cast<int>(fl.size(2)), CV_16UC3);
  auto enc = [](float x) {
    return static_cast<uint16_t>(std::lround(std::min(std::max(x * 64.f + 32768.f, 0.f), 65535.f)));
  };
  for (int y = 0; y < m.rows; ++y) {
    auto* row = m.ptr<cv::Vec3w>(y);
    for (int x = 0; x < m.cols; ++x) {
      const bool ok = v[y][x] > 0.5f;
      row[x] = cv::Vec3w(ok ? 1 : 0, ok ? enc(f[1][y][x]) : 0, ok ? enc(f[0][y][x]) : 0);
    }
  }
  write_raw(path, m);
}

torch::Tensor read_depth_png(const std::string& path) {
  cv::Mat m = read_raw(path, cv::IMREAD_UNCHANGED);
  if (m.depth() != CV_16U || m.channels() != 1)
    throw std::runtime_error("depth PNG '" + path + "' must be 16-bit single-channel (value/256), got " +
                             std::to_string(m.channels()) + " channel(s) of " + pixel_depth_name(m.depth()));
  cv::Mat f;
  m.convertTo(f, CV_32F, 1.0 / 256.0);
  return torch::from_blob(f.data, {1, f.rows, f.cols}, torch::kFloat32).clone();
}

void write_depth_png(const std::string& path, const torch::Tensor& depth) {
  auto d = depth.detach().to(torch::kCPU, torch::kFloat32);
  if (d.dim() == 3) d = d.squeeze(0);
  TORCH_CHECK(d.dim() == 2, "depth must be [1,H,W] or [H,W], got ", depth.sizes());
  d = (d.clamp(0, 65535.0 / 256.0) * 256).round().to(torch::kInt32).contiguous();
  cv::Mat m(static_cast<int>(d.size(0)), static_cast<int>(d.size(1)), CV_32S, d.data_ptr<int32_t>());
  cv::Mat m16;
  m.convertTo(m16, CV_16U);
  write_raw(path, m16);
}

torch::Tensor read_object_map(const std::string& path) {
  cv::Mat m = read_raw(path, cv::IMREAD_UNCHANGED);
  if (m.depth() != CV_8U || m.channels() != 1)
    throw std::runtime_error("object map '" + path + "' must be 8-bit single-channel (KITTI obj_map), got " +
                             std::to_string(m.channels()) + " channel(s) of " + pixel_depth_name(m.depth()));
  return torch::from_blob(m.data, {m.rows, m.cols}, torch::kUInt8).clone();
}

void write_object_map(const std::string& path, const torch::Tensor& objects) {
  auto o = objects.detach().to(torch::kCPU);
  if (o.dim() == 3 && o.size(0) == 1) o = o.squeeze(0);
  check_shape(o, "object map", {-1, -1});
  const double lo = o.min().item<double>(), hi = o.max().item<double>();
  if (lo < 0 || hi > 255)
    throw std::runtime_error("object map '" + path + "': values must lie in 0..255, got " + std::to_string(lo) + ".." +
                             std::to_string(hi));
  o = o.to(torch::kUInt8).contiguous();
  const cv::Mat m(static_cast<int>(o.size(0)), static_cast<int>(o.size(1)), CV_8UC1, o.data_ptr<uint8_t>());
  write_raw(path, m);
}

torch::Tensor colorize_disparity(const torch::Tensor& disp) {
  auto d = disp.detach().to(torch::kCPU, torch::kFloat32).reshape({disp.size(-2), disp.size(-1)});
  const float hi = std::max(d.max().item<float>(), 1e-6f);
  auto u8 = (d / hi * 255).clamp(0, 255).to(torch::kUInt8).contiguous();
  cv::Mat grey(static_cast<int>(u8.size(0)), static_cast<int>(u8.size(1)), CV_8U, u8.data_ptr<uint8_t>());
  cv::Mat colour;
  cv::applyColorMap(grey, colour, cv::COLORMAP_MAGMA);
  return mat_to_tensor(colour, "disparity");
}

torch::Tensor colorize_flow(const torch::Tensor& flow, double max_flow) {
  check_shape(flow, "flow", {2, -1, -1});
  auto f = flow.detach().to(torch::kCPU, torch::kFloat32);
  auto mag = f.pow(2).sum(0).sqrt();
  const double maxv = max_flow > 0 ? max_flow : std::max(mag.max().item<double>(), 1e-6);
  // HSV wheel: hue = direction, saturation = magnitude (Middlebury-style), value = 1.
  auto angle = torch::atan2(-f[1], -f[0]) / M_PI;   // [-1,1]
  auto hue = ((angle + 1) * 90).clamp(0, 179.999);  // OpenCV 8-bit hue range 0..180
  auto sat = (mag / maxv).clamp(0, 1) * 255;
  auto hsv = torch::stack({hue, sat, torch::full_like(hue, 255)}, 2).round().to(torch::kUInt8).contiguous();
  cv::Mat h(static_cast<int>(hsv.size(0)), static_cast<int>(hsv.size(1)), CV_8UC3, hsv.data_ptr<uint8_t>());
  cv::Mat bgr;
  cv::cvtColor(h, bgr, cv::COLOR_HSV2BGR);
  return mat_to_tensor(bgr, "flow");
}

}  // namespace geo
