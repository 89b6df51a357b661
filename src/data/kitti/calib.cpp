#include "data/kitti/calib.h"

#include "core/camera_rule.h"
#include "data/text_io.h"

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <tuple>

namespace geo {

const std::vector<double>& KeyValues::get(const std::string& key, size_t count) const {
  auto it = values.find(key);
  if (it == values.end()) throw std::runtime_error(source + ": missing calibration entry '" + key + "'");
  if (it->second.size() != count)
    throw std::runtime_error(source + ": calibration entry '" + key + "' has " + std::to_string(it->second.size()) +
                             " numbers, expected " + std::to_string(count));
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
  const auto problem =
      camera_problem(P[0][0].item<double>(), P[1][1].item<double>(), P[0][2].item<double>(), P[1][2].item<double>());
  if (!problem.empty()) throw std::runtime_error(source + ": calibration entry '" + key + "': " + problem);
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

std::pair<int64_t, int64_t> KeyValues::image_size(const std::string& key) const {
  const auto& s = get(key, 2);
  for (double v : s)
    if (!(v >= 1 && v <= 1e5 && v == std::floor(v)))  // (NaN fails too)
      throw std::runtime_error(source + ": calibration entry '" + key + "' is not an image size in pixels (" +
                               std::to_string(s[0]) + " x " + std::to_string(s[1]) +
                               "; whole numbers from 1 to 100000 expected)");
  return {static_cast<int64_t>(s[0]), static_cast<int64_t>(s[1])};
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
      throw std::runtime_error(where + ": key '" + key + "' is given twice (lines " + std::to_string(seen[key]) +
                               " and " + std::to_string(line_no) + "): which one is meant cannot be told");
    kv.values[key] = parse_doubles(rest, where);
  }
  return kv;
}

KeyValues read_key_values(const std::string& path) { return parse_key_values(read_text_file(path), path); }

torch::Tensor RawCalib::K() const {
  return P_rect.index({torch::indexing::Slice(), torch::indexing::Slice(0, 3)}).clone();
}

torch::Tensor RawCalib::img_from_velo() const { return P_rect.matmul(R_rect).matmul(cam_from_velo); }

RawCalib read_raw_calib(const std::string& date_dir, int camera, bool need_velo) {
  if (camera != 2 && camera != 3) throw std::invalid_argument("camera must be 2 or 3, got " + std::to_string(camera));
  const auto cam = read_key_values(date_dir + "/calib_cam_to_cam.txt");
  const std::string c = "0" + std::to_string(camera);
  RawCalib calib;
  calib.P_rect = cam.projection("P_rect_" + c);
  calib.R_rect = torch::eye(4, torch::kFloat64);
  calib.R_rect.index_put_({torch::indexing::Slice(0, 3), torch::indexing::Slice(0, 3)}, cam.rotation("R_rect_00"));
  if (cam.has("S_rect_" + c)) std::tie(calib.width, calib.height) = cam.image_size("S_rect_" + c);
  calib.cam_from_velo = torch::eye(4, torch::kFloat64);
  if (need_velo) {
    const auto velo = read_key_values(date_dir + "/calib_velo_to_cam.txt");
    calib.cam_from_velo.index_put_({torch::indexing::Slice(0, 3), torch::indexing::Slice(0, 3)}, velo.rotation("R"));
    calib.cam_from_velo.index_put_({torch::indexing::Slice(0, 3), 3}, velo.matrix("T", 3, 1).squeeze(1));
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
