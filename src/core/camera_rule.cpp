#include "core/camera_rule.h"

#include <cmath>
#include <cstdio>

namespace geo {

std::string camera_problem(double fx, double fy, double cx, double cy, int64_t width, int64_t height) {
  char text[320];
  auto plausible = [](double f) { return std::isfinite(f) && f >= 1 && f < 1e5; };
  if (!plausible(fx) || !plausible(fy)) {
    std::snprintf(text, sizeof text,
                  "focal lengths fx = %.6g, fy = %.6g are not plausible (in pixels: must be finite, >= 1 and < 1e5; "
                  "intrinsics normalised by the image size must be multiplied by it)",
                  fx, fy);
    return text;
  }
  if (width > 0 && height > 0) {
    if (!(cx >= 0 && cy >= 0 && cx <= static_cast<double>(width) && cy <= static_cast<double>(height))) {
      std::snprintf(text, sizeof text,
                    "principal point (%.6g, %.6g) lies outside the %lldx%lld frame (give it in pixels of the original "
                    "frames)",
                    cx, cy, static_cast<long long>(width), static_cast<long long>(height));
      return text;
    }
  } else if (!(std::abs(cx) < 1e5) || !(std::abs(cy) < 1e5)) {
    std::snprintf(text, sizeof text,
                  "principal point cx = %.6g, cy = %.6g is not plausible (must be within 1e5 pixels)", cx, cy);
    return text;
  }
  return "";
}

}  // namespace geo
