// KITTI calibration files (KITTI devkit formats): raw `calib_cam_to_cam.txt` / `calib_velo_to_cam.txt`,
// KITTI 2015 per-image `calib_cam_to_cam/%06d.txt` (same format), odometry `calib.txt`.
// All are "KEY: v v v ..." lines; non-numeric lines such as `calib_time:` are kept aside.
// Matrices are returned as CPU float64 tensors.
#pragma once

#include <torch/torch.h>

#include <map>
#include <string>
#include <vector>

namespace geo {

// Numeric entries of one calibration file, with the file it came from (for messages).
struct KeyValues {
  std::string source;
  std::map<std::string, std::vector<double>> values;
  bool has(const std::string& key) const { return values.count(key) > 0; }
  // The entry `key` with exactly `count` numbers; throws std::runtime_error naming file and key.
  const std::vector<double>& get(const std::string& key, size_t count) const;
  // get() as a [rows, cols] float64 tensor (row-major); non-finite values are an error.
  torch::Tensor matrix(const std::string& key, int64_t rows, int64_t cols) const;
  // A 3x4 projection matrix of a plausible camera (geometry/camera.h: camera_problem).
  torch::Tensor projection(const std::string& key) const;
  // A 3x3 rotation: orthonormal within 1e-2 and of determinant +1 (a zero or scaled matrix is not).
  torch::Tensor rotation(const std::string& key) const;
  // An image size "width height" (S_rect_0c): whole numbers of pixels in 1..100000, else an error
  // naming file and key.
  std::pair<int64_t, int64_t> image_size(const std::string& key) const;
};

// Parses "KEY: numbers" (or "KEY numbers") lines. Lines whose key is in `text_keys` (default:
// calib_time) are skipped; any other non-numeric value is an error naming source, line and key.
KeyValues parse_key_values(const std::string& text, const std::string& source);
KeyValues read_key_values(const std::string& path);

// Raw KITTI calibration of one date folder for one colour camera (2 = left, 3 = right).
struct RawCalib {
  torch::Tensor P_rect;           // [3,4] P_rect_0c
  torch::Tensor R_rect;           // [4,4] R_rect_00 padded with 1 (rectifying rotation of camera 0)
  torch::Tensor cam_from_velo;    // [4,4] [R|T] from calib_velo_to_cam.txt
  int64_t width = 0, height = 0;  // S_rect_0c (0 when the file has none)
  torch::Tensor K() const;        // [3,3] left 3x3 of P_rect
  // x_img = P_rect * R_rect * cam_from_velo * x_velo  ([3,4], KITTI devkit).
  torch::Tensor img_from_velo() const;
};
// Reads <date_dir>/calib_cam_to_cam.txt and calib_velo_to_cam.txt (the latter optional when
// `need_velo` is false). camera: 2 or 3.
RawCalib read_raw_calib(const std::string& date_dir, int camera = 2, bool need_velo = true);

// Odometry `sequences/XX/calib.txt`: P0..P3 [3,4] and Tr (velo -> cam0) as [4,4].
struct OdometryCalib {
  std::vector<torch::Tensor> P;  // P0..P3
  torch::Tensor Tr;              // [4,4]
};
OdometryCalib read_odometry_calib(const std::string& path);

// Formats a [rows, cols] tensor as space-separated numbers with full precision (for writers).
std::string format_numbers(const torch::Tensor& m);

}  // namespace geo
