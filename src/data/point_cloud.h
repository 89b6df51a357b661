// Coloured point clouds from depth, as PLY files (MeshLab, CloudCompare, Open3D, Blender read them).
#pragma once

#include <torch/torch.h>

#include <string>

namespace geo {

// Back-projects every pixel with 0 < depth <= max_depth (max_depth <= 0: no limit) through K [3,3]
// into camera coordinates (x right, y down, z forward) and writes them, coloured by `rgb` [3,H,W]
// (uint8, or float in [0,1]), as a binary little-endian PLY (float x, y, z; uchar red, green, blue), atomically.
// depth [1,H,W] or [H,W]. Returns the number of points written.
int64_t write_point_cloud_ply(const std::string& path, const torch::Tensor& depth, const torch::Tensor& rgb,
                              const torch::Tensor& K, double max_depth = 0);

}  // namespace geo
