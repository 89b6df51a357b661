#include "data/video/camera_motion.h"

#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

namespace geo {

namespace {

// A point pair in normalised camera coordinates (x = (u - cx) / fx, y = (v - cy) / fy).
struct Pair {
  double xa, ya, xb, yb;
};

struct Camera {
  double fx, fy, cx, cy;
};

cv::Matx33d rotation(const cv::Vec3d& w) {  // Rodrigues: exp([w]x)
  const double t = cv::norm(w);
  if (t < 1e-12) return cv::Matx33d::eye();
  const cv::Vec3d k = w / t;
  const cv::Matx33d K(0, -k[2], k[1], k[2], 0, -k[0], -k[1], k[0], 0);
  return cv::Matx33d::eye() + std::sin(t) * K + (1 - std::cos(t)) * (K * K);
}

// Where a rotation R of the camera takes a's point: x_b = R x_a, projected.
cv::Vec2d rotated(const cv::Matx33d& R, const Pair& p) {
  const cv::Vec3d q = R * cv::Vec3d(p.xa, p.ya, 1.0);
  return {q[0] / q[2], q[1] / q[2]};
}

// The residual of a pair under R in pixels.
double residual_px(const cv::Matx33d& R, const Pair& p, const Camera& c) {
  const auto r = rotated(R, p);
  return std::hypot(c.fx * (p.xb - r[0]), c.fy * (p.yb - r[1]));
}

// The rotation that best explains the pairs `idx` (least squares in pixels), refined from `R`: the
// image motion of a small rotation w at (x, y) is (-xy wx + (1+x^2) wy - y wz, -(1+y^2) wx + xy wy
// + x wz) (Longuet-Higgins & Prazdny), linearised at the current prediction; two steps.
cv::Matx33d fit_rotation(const std::vector<Pair>& pairs, const std::vector<size_t>& idx, const Camera& c,
                         cv::Matx33d R = cv::Matx33d::eye()) {
  for (int step = 0; step < 2; ++step) {
    cv::Mat A(static_cast<int>(2 * idx.size()), 3, CV_64F), b(static_cast<int>(2 * idx.size()), 1, CV_64F);
    for (size_t k = 0; k < idx.size(); ++k) {
      const auto& p = pairs[idx[k]];
      const auto r = rotated(R, p);
      const double x = r[0], y = r[1];
      const int i = static_cast<int>(2 * k);
      A.at<double>(i, 0) = c.fx * -x * y, A.at<double>(i, 1) = c.fx * (1 + x * x), A.at<double>(i, 2) = c.fx * -y;
      A.at<double>(i + 1, 0) = c.fy * -(1 + y * y), A.at<double>(i + 1, 1) = c.fy * x * y,
                          A.at<double>(i + 1, 2) = c.fy * x;
      b.at<double>(i) = c.fx * (p.xb - x);
      b.at<double>(i + 1) = c.fy * (p.yb - y);
    }
    cv::Mat w;
    if (!cv::solve(A, b, w, cv::DECOMP_SVD)) break;
    R = rotation({w.at<double>(0), w.at<double>(1), w.at<double>(2)}) * R;
  }
  return R;
}

std::vector<size_t> inliers(const cv::Matx33d& R, const std::vector<Pair>& pairs, const Camera& c, double threshold) {
  std::vector<size_t> in;
  for (size_t i = 0; i < pairs.size(); ++i)
    if (residual_px(R, pairs[i], c) < threshold) in.push_back(i);
  return in;
}

}  // namespace

cv::Mat motion_grey(const torch::Tensor& rgb) {
  TORCH_CHECK(rgb.dim() == 3 && rgb.size(0) == 3, "frame must be [3,H,W], got ", rgb.sizes());
  const auto scaled = rgb.is_floating_point() ? rgb.to(torch::kFloat32) * 255.0f : rgb.to(torch::kFloat32);
  // ITU-R BT.601 luma, as OpenCV's RGB -> grey.
  const auto grey = (0.299f * scaled[0] + 0.587f * scaled[1] + 0.114f * scaled[2])
                        .round()
                        .clamp(0, 255)
                        .to(torch::kUInt8)
                        .contiguous();
  return cv::Mat(static_cast<int>(grey.size(0)), static_cast<int>(grey.size(1)), CV_8UC1, grey.data_ptr<uint8_t>())
      .clone();
}

cv::Mat motion_grey(const cv::Mat& decoded) {
  cv::Mat grey = decoded;
  if (decoded.channels() == 3) cv::cvtColor(decoded, grey, cv::COLOR_BGR2GRAY);
  else if (decoded.channels() == 4) cv::cvtColor(decoded, grey, cv::COLOR_BGRA2GRAY);
  if (grey.depth() == CV_16U) grey.convertTo(grey, CV_8U, 1.0 / 257);
  TORCH_CHECK(grey.type() == CV_8UC1, "camera motion: an 8- or 16-bit image of 1, 3 or 4 channels expected");
  return grey;
}

CameraMotion camera_motion(const cv::Mat& a, const cv::Mat& b, const torch::Tensor& K, const CameraMotionOptions& o) {
  TORCH_CHECK(a.type() == CV_8UC1 && b.type() == CV_8UC1 && a.size() == b.size() && !a.empty(),
              "camera motion: two 8-bit grey images of one size expected");
  TORCH_CHECK(K.dim() == 2 && K.size(0) == 3 && K.size(1) == 3, "camera motion: K must be [3,3], got ", K.sizes());
  const auto k = K.to(torch::kFloat64).contiguous();
  const Camera cam{k[0][0].item<double>(), k[1][1].item<double>(), k[0][2].item<double>(), k[1][2].item<double>()};
  TORCH_CHECK(cam.fx > 0 && cam.fy > 0, "camera motion: the focal lengths must be positive");
  CameraMotion out;

  // Corners spread over the image (one per ~1/60 of its width), tracked there and back.
  std::vector<cv::Point2f> pa, pb, back;
  const double spacing = std::max(2.0, a.cols / 100.0);
  cv::goodFeaturesToTrack(a, pa, 500, 0.001, spacing, cv::noArray(), 3);
  if (static_cast<int64_t>(pa.size()) < kMinTrackedFeatures) return out;
  std::vector<uchar> ok, ok_back;
  std::vector<float> err;
  const cv::Size window(15, 15);
  const cv::TermCriteria stop(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.01);
  cv::calcOpticalFlowPyrLK(a, b, pa, pb, ok, err, window, 3, stop);
  cv::calcOpticalFlowPyrLK(b, a, pb, back, ok_back, err, window, 3, stop);
  std::vector<Pair> pairs;
  for (size_t i = 0; i < pa.size(); ++i) {
    if (!ok[i] || !ok_back[i] || cv::norm(back[i] - pa[i]) > 0.25) continue;
    pairs.push_back({(pa[i].x - cam.cx) / cam.fx, (pa[i].y - cam.cy) / cam.fy, (pb[i].x - cam.cx) / cam.fx,
                     (pb[i].y - cam.cy) / cam.fy});
  }
  out.tracked = static_cast<int64_t>(pairs.size());
  if (out.tracked < kMinTrackedFeatures) return out;
  const double threshold = o.parallax_px * static_cast<double>(a.cols) / static_cast<double>(kMotionWidth);

  // RANSAC over pairs of points (a rotation has 3 degrees of freedom, a point gives 2), seeded: the
  // same frames give the same answer.
  std::mt19937 rng(12345);
  std::uniform_int_distribution<size_t> pick(0, pairs.size() - 1);
  std::vector<size_t> best = inliers(cv::Matx33d::eye(), pairs, cam, threshold);
  for (int it = 0; it < 100; ++it) {
    const size_t i = pick(rng), j = pick(rng);
    if (i == j) continue;
    auto in = inliers(fit_rotation(pairs, {i, j}, cam), pairs, cam, threshold);
    if (in.size() > best.size()) best = std::move(in);
  }
  if (best.size() >= 2) {
    auto refined = inliers(fit_rotation(pairs, best, cam), pairs, cam, threshold);
    if (refined.size() > best.size()) best = std::move(refined);
  }
  // The share of the image, not of the points: a cell of a 4x3 grid votes still when most of its
  // points are, so that a textured truck or the car ahead does not outvote the road and buildings.
  std::vector<int> in_cell(12, 0), still_cell(12, 0);
  std::vector<char> is_still(pairs.size(), 0);
  for (size_t i : best) is_still[i] = 1;
  for (size_t i = 0; i < pairs.size(); ++i) {
    const double u = pairs[i].xa * cam.fx + cam.cx, v = pairs[i].ya * cam.fy + cam.cy;
    const int cx = std::clamp(static_cast<int>(4 * u / a.cols), 0, 3),
              cy = std::clamp(static_cast<int>(3 * v / a.rows), 0, 2);
    ++in_cell[cy * 4 + cx];
    still_cell[cy * 4 + cx] += is_still[i];
  }
  int voting = 0, still = 0;
  for (int k = 0; k < 12; ++k) {
    if (in_cell[k] < 2) continue;
    ++voting;
    still += 2 * still_cell[k] >= in_cell[k];
  }
  out.still_share = static_cast<double>(still) / static_cast<double>(voting);
  out.moved = out.still_share <= o.still_share;
  return out;
}

StandingCameraTest::StandingCameraTest(torch::Tensor K, CameraMotionOptions options)
    : K_(std::move(K)), options_(options) {}

bool StandingCameraTest::moved(const cv::Mat& grey) {
  if (last_kept_.empty()) return true;
  if (camera_motion(last_kept_, grey, K_, options_).moved) return true;
  return !previous_is_kept_ && camera_motion(previous_, grey, K_, options_).moved;
}

void StandingCameraTest::looked_at(const cv::Mat& grey, bool kept) {
  previous_ = grey;
  previous_is_kept_ = kept;
  if (kept) last_kept_ = grey;
}

}  // namespace geo
