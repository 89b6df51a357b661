#include "data/point_cloud.h"

#include "core/files.h"
#include "core/tensor_checks.h"
#include "geometry/camera.h"

#include <cstring>
#include <stdexcept>

namespace geo {

int64_t write_point_cloud_ply(const std::string& path, const torch::Tensor& depth, const torch::Tensor& rgb,
                              const torch::Tensor& K, double max_depth) {
  const auto d = (depth.dim() == 2 ? depth.unsqueeze(0) : depth).detach().to(torch::kCPU, torch::kFloat32);
  check_shape(d, "depth", {1, -1, -1});
  check_shape(rgb, "rgb", {3, d.size(1), d.size(2)});
  check_shape(K, "K", {3, 3});
  const auto points = back_project(d.unsqueeze(0), K.to(torch::kCPU, torch::kFloat32).unsqueeze(0))[0];  // [3,H,W]
  auto keep = (d[0] > 0) & torch::isfinite(d[0]);
  if (max_depth > 0) keep &= d[0] <= max_depth;
  const auto xyz = points.flatten(1).t().index({keep.flatten()}).contiguous();  // [N,3]
  const auto colour =
      (rgb.scalar_type() == torch::kUInt8
           ? rgb.detach().to(torch::kCPU)
           : (rgb.detach().to(torch::kCPU, torch::kFloat32).clamp(0, 1) * 255).round().to(torch::kUInt8))
          .flatten(1)
          .t()
          .index({keep.flatten()})
          .contiguous();  // [N,3]
  const int64_t n = xyz.size(0);
  std::string out =
      "ply\nformat binary_little_endian 1.0\ncomment written by geo (camera coordinates: x right, y down, "
      "z forward)\nelement vertex " +
      std::to_string(n) +
      "\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\n"
      "property uchar blue\nend_header\n";
  const size_t header = out.size();
  out.resize(header + static_cast<size_t>(n) * 15);
  const uint32_t probe = 1;
  uint8_t first_byte;
  std::memcpy(&first_byte, &probe, 1);
  if (first_byte != 1) throw std::runtime_error("write_point_cloud_ply: big-endian machines are not supported");
  const float* p = xyz.data_ptr<float>();
  const uint8_t* c = colour.data_ptr<uint8_t>();
  char* w = out.data() + header;
  for (int64_t i = 0; i < n; ++i, w += 15) {
    std::memcpy(w, p + 3 * i, 12);
    std::memcpy(w + 12, c + 3 * i, 3);
  }
  write_file_atomic(path, out);
  return n;
}

}  // namespace geo
