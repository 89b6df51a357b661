#include "data/video/clip_camera.h"

#include "core/camera_rule.h"
#include "data/kitti/calib.h"
#include "geometry/camera.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdio>
#include <tuple>

namespace geo {

namespace {

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

torch::Tensor from_calib_file(const std::string& path, int64_t width, int64_t height, const std::string& clip) {
  KeyValues kv;
  try {
    kv = read_key_values(path);
  } catch (const std::exception& e) {
    throw ConfigError("data.camera.calib_file: " + std::string(e.what()));
  }
  torch::Tensor K;
  int64_t cal_w = 0, cal_h = 0;
  if (kv.has("P_rect_02")) {
    K = kv.projection("P_rect_02").slice(1, 0, 3).clone();
    if (kv.has("S_rect_02")) std::tie(cal_w, cal_h) = kv.image_size("S_rect_02");
  } else if (kv.has("P2")) {
    K = kv.projection("P2").slice(1, 0, 3).clone();
  } else {
    throw ConfigError("data.camera.calib_file '" + path + "' has neither P_rect_02 (KITTI raw calib_cam_to_cam.txt) " +
                      "nor P2 (KITTI odometry calib.txt)");
  }
  if (cal_w > 0 && cal_h > 0 && (cal_w != width || cal_h != height)) {
    spdlog::warn(
        "data.camera.calib_file '{}' is for {}x{} frames but '{}' has {}x{}: its K is scaled to them "
        "(right when the frames were resized, wrong when they were cropped)",
        path, cal_w, cal_h, clip, width, height);
    K = resized_intrinsics(K, cal_h, cal_w, height, width);
  }
  return K.to(torch::kFloat64);
}

}  // namespace

torch::Tensor clip_camera(const CameraConfig& camera, int64_t width, int64_t height, const std::string& clip,
                          bool learned) {
  if (learned && !camera.given()) {
    CameraConfig nominal;
    nominal.fov_deg = 90;
    return clip_camera(nominal, width, height, clip);
  }
  torch::Tensor K;
  std::string key;
  if (!camera.intrinsics.empty()) {
    key = "data.camera.intrinsics";
    if (camera.intrinsics.size() != 4)
      throw ConfigError(key + " must be [fx, fy, cx, cy], got " + std::to_string(camera.intrinsics.size()) + " values");
    const auto& v = camera.intrinsics;
    K = torch::tensor({v[0], 0.0, v[2], 0.0, v[1], v[3], 0.0, 0.0, 1.0}, torch::kFloat64).view({3, 3});
  } else if (!camera.calib_file.empty()) {
    key = "data.camera.calib_file";
    K = from_calib_file(camera.calib_file, width, height, clip);
  } else if (camera.fov_deg != 0) {
    key = "data.camera.fov_deg";
    if (!(camera.fov_deg > 0 && camera.fov_deg < 180))
      throw ConfigError(key + " = " + number(camera.fov_deg) + ": must be in (0, 180) degrees");
    const double f = 0.5 * static_cast<double>(width) / std::tan(0.5 * camera.fov_deg * M_PI / 180.0);
    K = torch::tensor({f, 0.0, 0.5 * (width - 1.0), 0.0, f, 0.5 * (height - 1.0), 0.0, 0.0, 1.0}, torch::kFloat64)
            .view({3, 3});
  } else {
    throw ConfigError(
        "data.camera: no camera given for '" + clip + "' (" + std::to_string(width) + "x" + std::to_string(height) +
        "): set data.camera.intrinsics=[fx,fy,cx,cy] (pixels of the original " +
        "frames), data.camera.calib_file=<KITTI calib file> or data.camera.fov_deg=<horizontal field of view>, "
        "or learn it: model.learn_intrinsics=true");
  }
  const auto problem = camera_problem(K[0][0].item<double>(), K[1][1].item<double>(), K[0][2].item<double>(),
                                      K[1][2].item<double>(), width, height);
  if (!problem.empty()) throw ConfigError(key + ": " + problem + " ('" + clip + "')");
  return K;
}

std::string describe_camera(const torch::Tensor& K, int64_t width, int64_t height) {
  return "fx " + number(K[0][0].item<double>()) + " fy " + number(K[1][1].item<double>()) + " cx " +
         number(K[0][2].item<double>()) + " cy " + number(K[1][2].item<double>()) + " at " + std::to_string(width) +
         "x" + std::to_string(height);
}

}  // namespace geo
