#include "eval/metrics.h"

#include "core/tensor_checks.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace geo {

std::map<std::string, double> DepthErrors::as_map() const {
  return {{"abs_rel", abs_rel}, {"sq_rel", sq_rel}, {"rmse", rmse}, {"rmse_log", rmse_log},
          {"a1", a1},           {"a2", a2},         {"a3", a3}};
}

DepthErrors depth_errors(const torch::Tensor& gt_in, const torch::Tensor& pred_in) {
  TORCH_CHECK(gt_in.dim() == 1 && gt_in.sizes() == pred_in.sizes(),
              "depth_errors takes two 1-D tensors of equal length, got ", gt_in.sizes(), " and ", pred_in.sizes());
  DepthErrors e;
  e.pixels = gt_in.numel();
  if (e.pixels == 0) return e;
  const auto gt = gt_in.to(torch::kFloat64), pred = pred_in.to(torch::kFloat64);
  const auto thresh = torch::max(gt / pred, pred / gt);
  e.a1 = (thresh < 1.25).to(torch::kFloat64).mean().item<double>();
  e.a2 = (thresh < 1.25 * 1.25).to(torch::kFloat64).mean().item<double>();
  e.a3 = (thresh < 1.25 * 1.25 * 1.25).to(torch::kFloat64).mean().item<double>();
  e.rmse = (gt - pred).pow(2).mean().sqrt().item<double>();
  e.rmse_log = (gt.log() - pred.log()).pow(2).mean().sqrt().item<double>();
  e.abs_rel = ((gt - pred).abs() / gt).mean().item<double>();
  e.sq_rel = ((gt - pred).pow(2) / gt).mean().item<double>();
  return e;
}

double numpy_median(const torch::Tensor& values) {
  const auto v = std::get<0>(values.reshape({-1}).to(torch::kFloat64).sort());
  const int64_t n = v.numel();
  TORCH_CHECK(n > 0, "the median of no values");
  return n % 2 ? v[n / 2].item<double>() : 0.5 * (v[n / 2 - 1].item<double>() + v[n / 2].item<double>());
}

DepthErrors eigen_image_errors(const torch::Tensor& gt_in, const torch::Tensor& pred_in, const EigenOptions& o,
                               double* scale, double* median_ratio) {
  check_shape(gt_in, "ground-truth depth", {-1, -1});
  check_shape(pred_in, "predicted depth", {-1, -1});
  const int64_t H = gt_in.size(0), W = gt_in.size(1);
  auto gt = gt_in.to(torch::kFloat64);
  auto pred = pred_in.to(torch::kFloat64);
  if (pred.size(0) != H || pred.size(1) != W) {
    namespace F = torch::nn::functional;
    pred = F::interpolate(
               pred.view({1, 1, pred.size(0), pred.size(1)}),
               F::InterpolateFuncOptions().size(std::vector<int64_t>{H, W}).mode(torch::kBilinear).align_corners(false))
               .view({H, W});
  }
  auto mask = (gt > o.min_depth) & (gt < o.max_depth);
  if (o.garg_crop) {
    auto crop = torch::zeros({H, W}, torch::kBool);
    crop.slice(0, static_cast<int64_t>(0.40810811 * H), static_cast<int64_t>(0.99189189 * H))
        .slice(1, static_cast<int64_t>(0.03594771 * W), static_cast<int64_t>(0.96405229 * W))
        .fill_(true);
    mask &= crop;
  }
  auto g = gt.masked_select(mask), p = pred.masked_select(mask);
  if (g.numel() == 0) return {};
  const double ratio = numpy_median(g) / numpy_median(p);
  const double s = o.fixed_scale > 0 ? o.fixed_scale : o.median_scaling ? ratio : 1.0;
  if (scale) *scale = s;
  if (median_ratio) *median_ratio = ratio;
  return depth_errors(g, (p * s).clamp(o.min_depth, o.max_depth));
}

torch::Tensor resize_flow(const torch::Tensor& flow, int64_t H, int64_t W, FlowResize resize) {
  check_shape(flow, "flow", {2, -1, -1});
  const int64_t h = flow.size(1), w = flow.size(2);
  if (h == H && w == W) return flow;
  namespace F = torch::nn::functional;
  auto opts = F::InterpolateFuncOptions().size(std::vector<int64_t>{H, W});
  if (resize == FlowResize::kBilinear) opts.mode(torch::kBilinear).align_corners(false);
  else opts.mode(torch::kNearest);  // floor(x * w / W), as OpenCV's INTER_NEAREST
  auto r = F::interpolate(flow.unsqueeze(0).to(torch::kFloat32), opts)[0];
  auto factor = torch::tensor({static_cast<double>(W) / w, static_cast<double>(H) / h}, r.options()).view({2, 1, 1});
  return r * factor;
}

FlowErrorSums& FlowErrorSums::operator+=(const FlowErrorSums& other) {
  epe_sum += other.epe_sum;
  outliers += other.outliers;
  pixels += other.pixels;
  return *this;
}

FlowErrorSums flow_error_sums(const torch::Tensor& gt, const torch::Tensor& mask_in, const torch::Tensor& pred) {
  check_shape(gt, "ground-truth flow", {2, -1, -1});
  check_shape(pred, "predicted flow", {2, gt.size(1), gt.size(2)});
  const auto mask = mask_in.reshape({gt.size(1), gt.size(2)}).to(torch::kFloat32) > 0.5;
  const auto g = gt.to(torch::kFloat64);
  const auto epe = (pred.to(torch::kFloat64) - g).pow(2).sum(0).sqrt().masked_select(mask);
  const auto mag = g.pow(2).sum(0).sqrt().masked_select(mask);
  FlowErrorSums e;
  e.pixels = epe.numel();
  if (e.pixels == 0) return e;
  e.epe_sum = epe.sum().item<double>();
  e.outliers = ((epe > 3.0) & (epe > 0.05 * mag)).sum().item<int64_t>();
  return e;
}

FlowErrors flow_errors(const torch::Tensor& gt, const torch::Tensor& valid, const torch::Tensor& pred,
                       FlowResize resize) {
  check_shape(gt, "ground-truth flow", {2, -1, -1});
  const auto sums = flow_error_sums(gt, valid, resize_flow(pred, gt.size(1), gt.size(2), resize));
  FlowErrors e;
  e.pixels = sums.pixels;
  e.epe = sums.epe();
  e.fl = sums.fl();
  return e;
}

double least_squares_scale(const torch::Tensor& gt, const torch::Tensor& pred, double fallback) {
  const double denom = (pred * pred).sum().item<double>();
  return denom > 0 ? (gt * pred).sum().item<double>() / denom : fallback;
}

double snippet_ate(const torch::Tensor& gt_in, const torch::Tensor& pred_in) {
  check_shape(gt_in, "gt positions", {-1, 3});
  check_shape(pred_in, "predicted positions", {gt_in.size(0), 3});
  const auto gt = gt_in.to(torch::kFloat64);
  auto pred = pred_in.to(torch::kFloat64);
  pred = pred + (gt[0] - pred[0]);  // align the first frame
  const double s = least_squares_scale(gt, pred);
  return (s * pred - gt).pow(2).sum().sqrt().item<double>() / static_cast<double>(gt.size(0));
}

double aligned_trajectory_rmse(const torch::Tensor& gt_in, const torch::Tensor& pred_in) {
  check_shape(gt_in, "gt positions", {-1, 3});
  check_shape(pred_in, "predicted positions", {gt_in.size(0), 3});
  const auto gt = gt_in.to(torch::kFloat64), pred = pred_in.to(torch::kFloat64);
  const auto mu_g = gt.mean(0), mu_p = pred.mean(0);
  const auto g = gt - mu_g, p = pred - mu_p;
  const double n = static_cast<double>(gt.size(0));
  const auto cov = g.t().matmul(p) / n;  // Umeyama 1991: Sigma = 1/n sum (y - mu_y)(x - mu_x)^T
  auto [U, S, Vh] = torch::linalg_svd(cov, false);
  auto D = torch::eye(3, torch::kFloat64);
  if ((torch::det(U) * torch::det(Vh)).item<double>() < 0) D[2][2] = -1;
  const auto R = U.matmul(D).matmul(Vh);
  const double var_p = p.pow(2).sum().item<double>() / n;
  const double s = var_p > 0 ? (S * D.diagonal()).sum().item<double>() / var_p : 1.0;
  const auto t = mu_g - s * R.matmul(mu_p);
  const auto aligned = s * pred.matmul(R.t()) + t;
  return (aligned - gt).pow(2).sum(1).mean().sqrt().item<double>();
}

OdometryErrors kitti_odometry_errors(const torch::Tensor& gt_in, const torch::Tensor& pred_in,
                                     const std::vector<double>& lengths, int64_t step) {
  check_shape(gt_in, "gt poses", {-1, 4, 4});
  check_shape(pred_in, "predicted poses", {gt_in.size(0), 4, 4});
  if (step < 1) throw std::invalid_argument("kitti_odometry_errors: step must be >= 1");
  const auto gt = gt_in.to(torch::kFloat64).contiguous(), pred = pred_in.to(torch::kFloat64).contiguous();
  const int64_t n = gt.size(0);
  // Path length along the ground truth up to each frame.
  std::vector<double> dist(static_cast<size_t>(n), 0.0);
  const auto steps = (gt.slice(0, 1).select(2, 3).slice(1, 0, 3) - gt.slice(0, 0, n - 1).select(2, 3).slice(1, 0, 3))
                         .norm(2, 1)
                         .contiguous();
  for (int64_t i = 1; i < n; ++i) dist[i] = dist[i - 1] + steps[i - 1].item<double>();
  OdometryErrors out;
  double t_sum = 0, r_sum = 0;
  for (int64_t first = 0; first < n; first += step) {
    for (const double len : lengths) {
      int64_t last = -1;
      for (int64_t i = first; i < n; ++i)
        if (dist[i] > dist[first] + len) {
          last = i;
          break;
        }
      if (last < 0) continue;
      const auto delta_gt = torch::inverse(gt[first]).matmul(gt[last]);
      const auto delta_pred = torch::inverse(pred[first]).matmul(pred[last]);
      const auto e = torch::inverse(delta_pred).matmul(delta_gt);
      const double d = 0.5 * (e[0][0].item<double>() + e[1][1].item<double>() + e[2][2].item<double>() - 1.0);
      r_sum += std::acos(std::max(std::min(d, 1.0), -1.0)) / len;
      t_sum += e.slice(0, 0, 3).select(1, 3).norm().item<double>() / len;
      ++out.segments;
    }
  }
  if (out.segments > 0) {
    out.t_err = t_sum / static_cast<double>(out.segments);
    out.r_err = r_sum / static_cast<double>(out.segments);
  }
  return out;
}

std::pair<torch::Tensor, torch::Tensor> align_trajectory_scale(const torch::Tensor& gt_in,
                                                               const torch::Tensor& pred_in) {
  check_shape(gt_in, "gt poses", {-1, 4, 4});
  check_shape(pred_in, "predicted poses", {gt_in.size(0), 4, 4});
  const auto gt0 = gt_in.to(torch::kFloat64), pred0 = pred_in.to(torch::kFloat64);
  const auto gt = torch::inverse(gt0[0]).unsqueeze(0).matmul(gt0);
  auto pred = torch::inverse(pred0[0]).unsqueeze(0).matmul(pred0);
  const double scale = least_squares_scale(gt.slice(1, 0, 3).select(2, 3), pred.slice(1, 0, 3).select(2, 3));
  pred.slice(1, 0, 3).select(2, 3).mul_(scale);
  return {gt, pred};
}

bool trajectory_moves(const torch::Tensor& poses) {
  check_shape(poses, "poses", {-1, 4, 4});
  const auto p = poses.to(torch::kFloat64).slice(1, 0, 3).select(2, 3);  // [N,3]
  return p.size(0) > 0 && (p - p[0]).norm(2, 1).max().item<double>() > 1e-9;
}

}  // namespace geo
