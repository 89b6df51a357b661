// Small text-file helpers shared by the KITTI readers: whole-file reads, number parsing with
// messages that name the file and line, KITTI pose files, Velodyne scans and NumPy arrays.
#pragma once

#include <torch/torch.h>

#include <string>
#include <vector>

namespace geo {

// Reads a whole file; throws std::runtime_error "cannot open '<path>'" when missing/unreadable.
std::string read_text_file(const std::string& path);

std::string trim(const std::string& s);

// Parses whitespace-separated numbers; a token that is not a number throws naming `where` and it.
std::vector<double> parse_doubles(const std::string& text, const std::string& where);

// KITTI pose file (odometry poses/XX.txt): one 3x4 row-major camera-to-world matrix a line.
// -> [N,4,4] float64. Lines with other than 12 numbers are errors naming file and line.
torch::Tensor read_poses(const std::string& path);
// Writes [N,4,4] (or [N,3,4]) as a KITTI pose file, atomically.
void write_poses(const std::string& path, const torch::Tensor& poses);

// Velodyne scan: float32 x, y, z, reflectance. -> [N,4] float32. A size that is not a multiple of
// 16 bytes is an error naming the file (truncated download).
torch::Tensor read_velodyne(const std::string& path);
void write_velodyne(const std::string& path, const torch::Tensor& points);

// NumPy .npy (format 1 to 3) of little-endian float32 / float64, C order -> float32 tensor. Anything
// else (other dtypes, Fortran order, a header or data running past the end) is an error naming the file.
torch::Tensor read_npy(const std::string& path);

// Text file as lines (trailing '\r' removed, blank lines dropped).
std::vector<std::string> read_lines(const std::string& path);

}  // namespace geo
