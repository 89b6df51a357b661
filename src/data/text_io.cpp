#include "data/text_io.h"

#include "core/files.h"

#include <cerrno>
#include <cstdlib>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
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
      throw std::runtime_error(where + ": expected 12 numbers (a 3x4 pose), got " + std::to_string(v.size()));
    for (double x : v)
      if (!std::isfinite(x)) throw std::runtime_error(where + ": a pose holds NaN or infinity");
    // The 3x3 part must be a rotation: an all-zero or scaled one cannot be inverted or chained.
    const double det =
        v[0] * (v[5] * v[10] - v[6] * v[9]) - v[1] * (v[4] * v[10] - v[6] * v[8]) + v[2] * (v[4] * v[9] - v[5] * v[8]);
    if (std::abs(det - 1.0) > 1e-2)
      throw std::runtime_error(where + ": the rotation part has determinant " + std::to_string(det) +
                               " (a rotation has 1): not a camera pose");
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
  if (n > 0) std::memcpy(t.data_ptr<float>(), bytes.data(), bytes.size());  // an empty tensor has no buffer
  return t;
}

void write_velodyne(const std::string& path, const torch::Tensor& points) {
  TORCH_CHECK(points.dim() == 2 && points.size(1) == 4, "points must be [N,4], got ", points.sizes());
  auto p = points.to(torch::kFloat32).contiguous();
  write_file_atomic(path, std::string(reinterpret_cast<const char*>(p.data_ptr<float>()),
                                      static_cast<size_t>(p.numel()) * sizeof(float)));
}

torch::Tensor read_npy(const std::string& path) {
  const std::string bytes = read_text_file(path);
  if (bytes.size() < 10 || bytes.compare(0, 6, "\x93NUMPY") != 0)
    throw std::runtime_error(path + ": not a NumPy .npy file");
  const int major = static_cast<unsigned char>(bytes[6]);
  if (major < 1 || major > 3)
    throw std::runtime_error(path + ": NumPy format version " + std::to_string(major) + " is not supported (1 to 3)");
  auto byte = [&](size_t i) { return static_cast<size_t>(static_cast<unsigned char>(bytes[i])); };
  const size_t start = major == 1 ? 10 : 12;
  if (bytes.size() < start) throw std::runtime_error(path + ": truncated header");
  const size_t hlen =
      major == 1 ? (byte(8) | byte(9) << 8) : (byte(8) | byte(9) << 8 | byte(10) << 16 | byte(11) << 24);
  if (hlen > bytes.size() - start)
    throw std::runtime_error(path + ": header of " + std::to_string(hlen) + " bytes runs past the end of the file");
  const std::string header = bytes.substr(start, hlen);
  // The header is a Python dict literal: each key's value read whatever the spacing around ':'.
  const auto field = [&](const std::string& key) {
    size_t k = header.find("'" + key + "'");
    if (k == std::string::npos) k = header.find("\"" + key + "\"");
    if (k == std::string::npos) throw std::runtime_error(path + ": header has no '" + key + "'");
    size_t i = header.find_first_not_of(" \t", k + key.size() + 2);
    if (i == std::string::npos || header[i] != ':')
      throw std::runtime_error(path + ": malformed header at '" + key + "'");
    i = header.find_first_not_of(" \t", i + 1);
    if (i == std::string::npos) throw std::runtime_error(path + ": malformed header at '" + key + "'");
    size_t j = i;
    for (int depth = 0; j < header.size(); ++j) {
      if (header[j] == '(') ++depth;
      if (header[j] == ')') --depth;
      if (depth == 0 && (header[j] == ',' || header[j] == '}')) break;
    }
    return trim(header.substr(i, j - i));
  };
  const std::string descr = field("descr"), order = field("fortran_order"), shape_text = field("shape");
  const bool f4 = descr == "'<f4'" || descr == "\"<f4\"", f8 = descr == "'<f8'" || descr == "\"<f8\"";
  if (!f4 && !f8)
    throw std::runtime_error(path + ": 'descr' is " + descr +
                             ": only little-endian float32/float64 arrays are supported ('<f4' or '<f8')");
  if (order == "True")
    throw std::runtime_error(path + ": Fortran-order arrays are not supported (save with np.ascontiguousarray)");
  if (order != "False") throw std::runtime_error(path + ": 'fortran_order' is '" + order + "' (True or False)");
  const auto a = shape_text.find('('), b = shape_text.rfind(')');
  if (a != 0 || b != shape_text.size() - 1)
    throw std::runtime_error(path + ": 'shape' is '" + shape_text + "', not a tuple");
  const std::string header_shape = shape_text;
  std::vector<int64_t> shape;
  std::istringstream dims(header_shape.substr(a + 1, b - a - 1));
  std::string tok;
  const int64_t elem = f4 ? 4 : 8;
  int64_t count = 1;
  while (std::getline(dims, tok, ',')) {
    tok = trim(tok);
    if (tok.empty()) continue;
    char* end = nullptr;
    errno = 0;
    const long long d = std::strtoll(tok.c_str(), &end, 10);
    if (errno != 0 || *end != '\0' || d < 0 || shape.size() >= 8)
      throw std::runtime_error(path + ": bad shape entry '" + tok + "' (non-negative integers, at most 8 dimensions)");
    if (d > 0 && count > std::numeric_limits<int64_t>::max() / elem / d)
      throw std::runtime_error(path + ": shape is too large");
    count *= d;
    shape.push_back(d);
  }
  const auto need = static_cast<size_t>(count * elem);
  if (bytes.size() - start - hlen < need)
    throw std::runtime_error(path + ": truncated array data (" + std::to_string(bytes.size() - start - hlen) +
                             " bytes, the shape needs " + std::to_string(need) + ")");
  auto t = torch::empty(shape, f4 ? torch::kFloat32 : torch::kFloat64);
  if (need > 0) std::memcpy(t.data_ptr(), bytes.data() + start + hlen, need);
  return t.to(torch::kFloat32);
}

}  // namespace geo
