#include "data/kitti/calib.h"

#include <cstdio>

#include "data/text_io.h"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace geo {

const std::vector<double>& KeyValues::get(const std::string& key, size_t count) const {
  auto it = values.find(key);
  if (it == values.end())
    throw std::runtime_error(source + ": missing calibration entry '" + key + "'");
  if (it->second.size() != count)
    throw std::runtime_error(source + ": calibration entry '" + key + "' has " +
                             std::to_string(it->second.size()) + " numbers, expected " +
                             std::to_string(count));
  return it->second;
}

torch::Tensor KeyValues::matrix(const std::string& key, int64_t rows, int64_t cols) const {
  const auto& v = get(key, static_cast<size_t>(rows * cols));
  for (double x : v)
    if (!std::isfinite(x))
      throw std::runtime_error(source + ": calibration entry '" + key + "' holds a non-finite value (" +
                               std::to_string(x) + ")");
  return torch::tensor(v, torch::kFloat64).reshape({rows, cols});
}

torch::Tensor KeyValues::projection(const std::string& key) const {
  const auto P = matrix(key, 3, 4);
  const double fx = P[0][0].item<double>(), fy = P[1][1].item<double>();
  check_focal_lengths(fx, fy, source + ": calibration entry '" + key + "'");
  // The principal point lies near the image: within 1e5 pixels of its corner (KITTI: ~600, ~180).
  const double cx = P[0][2].item<double>(), cy = P[1][2].item<double>();
  if (!(std::abs(cx) < 1e5) || !(std::abs(cy) < 1e5))
    throw std::runtime_error(source + ": calibration entry '" + key + "': principal point cx = " + std::to_string(cx) +
                             ", cy = " + std::to_string(cy) + " is not plausible (must be within 1e5 pixels)");
  return P;
}

torch::Tensor KeyValues::rotation(const std::string& key) const {
  const auto R = matrix(key, 3, 3);
  const double off = (R.matmul(R.t()) - torch::eye(3, torch::kFloat64)).abs().max().item<double>();
  const double det = torch::det(R).item<double>();
  if (!(off < 1e-2) || !(det > 0))
    throw std::runtime_error(source + ": calibration entry '" + key + "' is not a rotation (R R^T differs from I by " +
                             std::to_string(off) + ", det " + std::to_string(det) + ")");
  return R;
}

void check_focal_lengths(double fx, double fy, const std::string& what) {
  // From 1 to 1e5 px (KITTI: ~720 px; below 1 px the field of view passes 180 degrees, a 1e5 px
  // focal length is 0.4 degrees): normalised intrinsics (fx ~ 0.6) are the mistake this catches.
  auto ok = [](double f) { return std::isfinite(f) && f >= 1 && f < 1e5; };
  if (!ok(fx) || !ok(fy)) {
    char text[200];
    std::snprintf(text, sizeof text, ": focal lengths fx = %.6g, fy = %.6g are not plausible", fx, fy);
    throw std::runtime_error(what + text + " (in pixels: must be finite, >= 1 and < 1e5; intrinsics normalised by the "
                                           "image size must be multiplied by it)");
  }
}

KeyValues parse_key_values(const std::string& text, const std::string& source) {
  KeyValues kv;
  kv.source = source;
  std::istringstream in(text);
  std::string line;
  int line_no = 0;
  std::map<std::string, int> seen;  // key -> line
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.find_first_not_of(" \t") == std::string::npos) continue;
    std::string key, rest;
    auto colon = line.find(':');
    if (colon != std::string::npos) {
      key = line.substr(0, colon);
      rest = line.substr(colon + 1);
    } else {
      std::istringstream ls(line);
      ls >> key;
      std::getline(ls, rest);
    }
    key = trim(key);
    if (key == "calib_time") continue;  // a date, not numbers (raw KITTI)
    const std::string where = source + " line " + std::to_string(line_no) + " ('" + key + "')";
    if (!seen.emplace(key, line_no).second)
      throw std::runtime_error(where + ": key '" + key + "' is given twice (lines " + std::to_string(seen[key]) + " and " +
                               std::to_string(line_no) + "): which one is meant cannot be told");
    kv.values[key] = parse_doubles(rest, where);
  }
  return kv;
}

KeyValues read_key_values(const std::string& path) {
  return parse_key_values(read_text_file(path), path);
}

torch::Tensor RawCalib::K() const { return P_rect.index({torch::indexing::Slice(), torch::indexing::Slice(0, 3)}).clone(); }

torch::Tensor RawCalib::img_from_velo() const {
  return P_rect.matmul(R_rect).matmul(cam_from_velo);
}

RawCalib read_raw_calib(const std::string& date_dir, int camera, bool need_velo) {
  if (camera != 2 && camera != 3)
    throw std::invalid_argument("camera must be 2 or 3, got " + std::to_string(camera));
  const auto cam = read_key_values(date_dir + "/calib_cam_to_cam.txt");
  const std::string c = "0" + std::to_string(camera);
  RawCalib calib;
  calib.P_rect = cam.projection("P_rect_" + c);
  calib.R_rect = torch::eye(4, torch::kFloat64);
  calib.R_rect.index_put_({torch::indexing::Slice(0, 3), torch::indexing::Slice(0, 3)},
                          cam.rotation("R_rect_00"));
  if (cam.has("S_rect_" + c)) {
    const auto& s = cam.get("S_rect_" + c, 2);
    calib.width = static_cast<int64_t>(s[0]);
    calib.height = static_cast<int64_t>(s[1]);
  }
  calib.cam_from_velo = torch::eye(4, torch::kFloat64);
  if (need_velo) {
    const auto velo = read_key_values(date_dir + "/calib_velo_to_cam.txt");
    calib.cam_from_velo.index_put_({torch::indexing::Slice(0, 3), torch::indexing::Slice(0, 3)},
                                   velo.rotation("R"));
    calib.cam_from_velo.index_put_({torch::indexing::Slice(0, 3), 3},
                                   velo.matrix("T", 3, 1).squeeze(1));
  }
  return calib;
}

OdometryCalib read_odometry_calib(const std::string& path) {
  const auto kv = read_key_values(path);
  OdometryCalib calib;
  for (int i = 0; i < 4; ++i) calib.P.push_back(kv.projection("P" + std::to_string(i)));
  calib.Tr = torch::eye(4, torch::kFloat64);
  calib.Tr.index_put_({torch::indexing::Slice(0, 3)}, kv.matrix("Tr", 3, 4));
  return calib;
}

std::string format_numbers(const torch::Tensor& m) {
  auto flat = m.to(torch::kFloat64).contiguous().reshape({-1});
  std::ostringstream out;
  out.precision(12);
  for (int64_t i = 0; i < flat.numel(); ++i) out << (i ? " " : "") << flat[i].item<double>();
  return out.str();
}

}  // namespace geo
