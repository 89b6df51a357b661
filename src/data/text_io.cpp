#include "data/text_io.h"

#include "core/files.h"

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>

namespace geo {

std::string read_text_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw std::runtime_error("cannot open '" + path + "' (missing or unreadable)");
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

std::vector<double> parse_doubles(const std::string& text, const std::string& where) {
  std::vector<double> out;
  std::istringstream in(text);
  std::string tok;
  while (in >> tok) {
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(tok.c_str(), &end);
    if (end == tok.c_str() || *end != '\0' || errno == ERANGE)
      throw std::runtime_error(where + ": '" + tok + "' is not a number");
    out.push_back(v);
  }
  return out;
}

std::vector<std::string> read_lines(const std::string& path) {
  std::istringstream in(read_text_file(path));
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(in, line)) {
    line = trim(line);
    if (!line.empty()) lines.push_back(line);
  }
  return lines;
}

torch::Tensor read_poses(const std::string& path) {
  std::istringstream in(read_text_file(path));
  std::vector<double> all;
  std::string line;
  int line_no = 0;
  int64_t n = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (trim(line).empty()) continue;
    const std::string where = path + " line " + std::to_string(line_no);
    auto v = parse_doubles(line, where);
    if (v.size() != 12)
      throw std::runtime_error(where + ": expected 12 numbers (a 3x4 pose), got " +
                               std::to_string(v.size()));
    all.insert(all.end(), v.begin(), v.end());
    all.insert(all.end(), {0.0, 0.0, 0.0, 1.0});
    ++n;
  }
  if (n == 0) throw std::runtime_error(path + ": no poses");
  return torch::tensor(all, torch::kFloat64).reshape({n, 4, 4});
}

void write_poses(const std::string& path, const torch::Tensor& poses) {
  TORCH_CHECK(poses.dim() == 3 && poses.size(2) == 4 && (poses.size(1) == 3 || poses.size(1) == 4),
              "poses must be [N,4,4] or [N,3,4], got ", poses.sizes());
  auto p = poses.to(torch::kFloat64).contiguous();
  std::ostringstream out;
  out.precision(9);
  out << std::scientific;
  for (int64_t i = 0; i < p.size(0); ++i) {
    const auto row = p[i];
    auto a = row.accessor<double, 2>();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) out << a[r][c] << ((r == 2 && c == 3) ? "\n" : " ");
  }
  write_file_atomic(path, out.str());
}

torch::Tensor read_velodyne(const std::string& path) {
  const std::string bytes = read_text_file(path);
  if (bytes.size() % 16 != 0)
    throw std::runtime_error(path + ": Velodyne scan size " + std::to_string(bytes.size()) +
                             " bytes is not a multiple of 16 (float32 x,y,z,r; truncated?)");
  const int64_t n = static_cast<int64_t>(bytes.size() / 16);
  auto t = torch::empty({n, 4}, torch::kFloat32);
  std::memcpy(t.data_ptr<float>(), bytes.data(), bytes.size());
  return t;
}

void write_velodyne(const std::string& path, const torch::Tensor& points) {
  TORCH_CHECK(points.dim() == 2 && points.size(1) == 4, "points must be [N,4], got ",
              points.sizes());
  auto p = points.to(torch::kFloat32).contiguous();
  write_file_atomic(path, std::string(reinterpret_cast<const char*>(p.data_ptr<float>()),
                                      static_cast<size_t>(p.numel()) * sizeof(float)));
}

}  // namespace geo
