#include "geometry/road_plane.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <stdexcept>

namespace geo {
namespace {

using Vec3 = std::array<double, 3>;

Vec3 sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

struct Plane {
  Vec3 n{};      // unit, n[1] > 0 (down)
  double h = 0;  // n.X = h on the plane (the camera's distance from it)
};

// Points within band x h of the plane.
std::vector<size_t> inliers_of(const Plane& p, const std::vector<Vec3>& pts, double band) {
  std::vector<size_t> in;
  for (size_t i = 0; i < pts.size(); ++i)
    if (std::abs(dot(p.n, pts[i]) - p.h) < band * p.h) in.push_back(i);
  return in;
}

// Least squares: the plane through the inliers' centroid normal to their smallest principal axis.
bool refit(const std::vector<Vec3>& pts, const std::vector<size_t>& in, Plane* out) {
  if (in.size() < 3) return false;
  Vec3 c{0, 0, 0};
  for (size_t i : in)
    for (int k = 0; k < 3; ++k) c[k] += pts[i][k];
  for (int k = 0; k < 3; ++k) c[k] /= static_cast<double>(in.size());
  auto cov = torch::zeros({3, 3}, torch::kFloat64);
  auto a = cov.accessor<double, 2>();
  for (size_t i : in) {
    const Vec3 d = sub(pts[i], c);
    for (int r = 0; r < 3; ++r)
      for (int s = 0; s < 3; ++s) a[r][s] += d[r] * d[s];
  }
  const auto eig = torch::linalg_eigh(cov);  // ascending eigenvalues
  const auto v = std::get<1>(eig).select(1, 0);
  Vec3 n{v[0].item<double>(), v[1].item<double>(), v[2].item<double>()};
  if (n[1] < 0) n = {-n[0], -n[1], -n[2]};
  const double h = dot(n, c);
  if (!(h > 0)) return false;
  *out = Plane{n, h};
  return true;
}

}  // namespace

RoadPlane fit_road_plane(const torch::Tensor& depth_in, const torch::Tensor& K_in, const RoadPlaneOptions& o) {
  auto depth = depth_in.detach().to(torch::kCPU, torch::kFloat64);
  if (depth.dim() == 3 && depth.size(0) == 1) depth = depth[0];
  if (depth.dim() != 2)
    throw std::invalid_argument("fit_road_plane: depth must be [H,W], got " + c10::str(depth.sizes()));
  const auto K = K_in.detach().to(torch::kCPU, torch::kFloat64);
  if (K.sizes() != torch::IntArrayRef{3, 3}) throw std::invalid_argument("fit_road_plane: K must be [3,3]");
  const double fx = K[0][0].item<double>(), fy = K[1][1].item<double>(), cx = K[0][2].item<double>(),
               cy = K[1][2].item<double>();
  if (!(fx > 0) || !(fy > 0)) throw std::invalid_argument("fit_road_plane: K's focal lengths must be > 0");
  const int64_t H = depth.size(0), W = depth.size(1);
  const int64_t top = std::min<int64_t>(H - 1, static_cast<int64_t>(std::floor(H * (1.0 - o.bottom_fraction))));
  const int64_t candidates = (H - top) * W;
  const int64_t stride = std::max<int64_t>(1, (candidates + o.max_points - 1) / std::max<int64_t>(o.max_points, 1));
  const auto d = depth.contiguous();
  const double* z = d.data_ptr<double>();
  std::vector<Vec3> pts;
  for (int64_t k = 0; k < candidates; k += stride) {
    const int64_t v = top + k / W, u = k % W;
    const double zz = z[v * W + u];
    if (!(zz > 0) || !std::isfinite(zz)) continue;
    pts.push_back({(static_cast<double>(u) - cx) / fx * zz, (static_cast<double>(v) - cy) / fy * zz, zz});
  }
  RoadPlane out;
  out.points = static_cast<int64_t>(pts.size());
  if (pts.size() < 3) {
    out.why = "fewer than 3 valid depths in the lowest " + std::to_string(static_cast<int>(o.bottom_fraction * 100)) +
              "% of the image";
    return out;
  }
  // The final plane: found when enough of the points lie on it (both fits end here).
  const auto accept = [&](const Plane& p, const char* kind) {
    const auto in = inliers_of(p, pts, o.inlier_band);
    out.inliers = static_cast<int64_t>(in.size());
    if (static_cast<double>(in.size()) < o.min_inlier_fraction * static_cast<double>(pts.size())) {
      out.why = "only " + std::to_string(in.size()) + " of " + std::to_string(pts.size()) +
                " points of the lower image lie on one " + kind;
      return out;
    }
    out.found = true;
    out.height = p.h;
    for (int k = 0; k < 3; ++k) out.normal[k] = p.n[k];
    return out;
  };
  const double min_cos = std::cos(o.max_tilt_deg * M_PI / 180.0);
  std::mt19937_64 rng(o.seed);
  std::uniform_int_distribution<size_t> pick(0, pts.size() - 1);
  Plane best;
  size_t best_count = 0;
  if (o.level_camera) {
    for (int it = 0; it < o.iterations; ++it) {
      const Plane p{{0, 1, 0}, pts[pick(rng)][1]};
      if (!(p.h > 0)) continue;  // a point above the camera: not the road
      const size_t count = inliers_of(p, pts, o.inlier_band).size();
      if (count > best_count) best = p, best_count = count;
    }
    if (best_count == 0) {
      out.why = "no point of the lower image lies below the camera";
      return out;
    }
    for (int round = 0; round < 2; ++round) {
      const auto in = inliers_of(best, pts, o.inlier_band);
      double sum = 0;
      for (size_t i : in) sum += pts[i][1];
      if (!in.empty()) best.h = sum / static_cast<double>(in.size());
    }
    return accept(best, "level road plane");
  }
  for (int it = 0; it < o.iterations; ++it) {
    const Vec3 &a = pts[pick(rng)], &b = pts[pick(rng)], &c = pts[pick(rng)];
    Vec3 n = cross(sub(b, a), sub(c, a));
    const double len = std::sqrt(dot(n, n));
    if (!(len > 0)) continue;
    for (double& x : n) x /= len;
    if (n[1] < 0) n = {-n[0], -n[1], -n[2]};
    if (n[1] < min_cos) continue;  // too steep for a road
    const Plane p{n, dot(n, a)};
    if (!(p.h > 0)) continue;  // the camera must be above it
    const size_t count = inliers_of(p, pts, o.inlier_band).size();
    if (count > best_count) best = p, best_count = count;
  }
  if (best_count == 0) {
    out.why = "no plane within " + std::to_string(static_cast<int>(o.max_tilt_deg)) +
              " degrees of horizontal below the camera";
    return out;
  }
  Plane fitted = best;
  for (int round = 0; round < 2; ++round) {
    Plane next;
    if (!refit(pts, inliers_of(fitted, pts, o.inlier_band), &next)) break;
    fitted = next;
  }
  if (fitted.n[1] < min_cos) {
    out.inliers = static_cast<int64_t>(inliers_of(fitted, pts, o.inlier_band).size());
    out.why = "the fitted plane is tilted more than " + std::to_string(static_cast<int>(o.max_tilt_deg)) + " degrees";
    return out;
  }
  return accept(fitted, "road plane");
}

double camera_height_scale(const RoadPlane& plane, double known_height) {
  return plane.found && plane.height > 0 ? known_height / plane.height : 0.0;
}

std::vector<double> smooth_scales(const std::vector<double>& scales, int radius) {
  std::vector<double> out(scales.size(), 0.0);
  const int64_t n = static_cast<int64_t>(scales.size());
  for (int64_t i = 0; i < n; ++i) {
    std::vector<double> window;
    for (int64_t j = std::max<int64_t>(0, i - radius); j <= std::min<int64_t>(n - 1, i + radius); ++j)
      if (scales[static_cast<size_t>(j)] > 0) window.push_back(scales[static_cast<size_t>(j)]);
    if (window.empty()) continue;
    std::sort(window.begin(), window.end());
    const size_t m = window.size();
    out[static_cast<size_t>(i)] = m % 2 ? window[m / 2] : 0.5 * (window[m / 2 - 1] + window[m / 2]);
  }
  return out;
}

}  // namespace geo
