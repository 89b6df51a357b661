#include "losses/total_loss.h"

#include "geometry/camera.h"
#include "core/tensor_checks.h"
#include "geometry/pose.h"
#include "geometry/warp.h"
#include "losses/consistency.h"
#include "losses/photometric.h"
#include "losses/smoothness.h"

namespace geo {

namespace {

// Per-pixel mask for one direction and source: ones, times the in-view mask and the auto-mask.
torch::Tensor loss_mask(const torch::Tensor& error, const torch::Tensor& valid, const torch::Tensor& identity_error,
                        const LossConfig& cfg) {
  auto mask = torch::ones_like(error);
  if (cfg.mask_out_of_view) mask = mask * valid;
  if (cfg.automask) mask = mask * (error < identity_error).to(error.dtype());
  return mask;
}

// Photometric term of one direction at one scale over all sources. With auto-masking, `masked`
// (when given) receives the share of pixels a still frame explained better (no gradient).
torch::Tensor direction_loss(const std::vector<torch::Tensor>& errors, const std::vector<torch::Tensor>& valids,
                             const std::vector<torch::Tensor>& identity, const LossConfig& cfg,
                             torch::Tensor* masked = nullptr) {
  const auto share = [&](const torch::Tensor& err, const torch::Tensor& ident) {
    if (masked && cfg.automask) *masked = (err.detach() >= ident).to(torch::kFloat32).mean();
  };
  if (cfg.min_reprojection) {
    const auto err = std::get<0>(torch::stack(errors).min(0));
    auto valid = torch::stack(valids).amax(0);
    torch::Tensor ident = cfg.automask ? std::get<0>(torch::stack(identity).min(0)) : err;
    share(err, ident);
    return masked_mean(err, loss_mask(err, valid, ident, cfg));
  }
  if (cfg.automask) share(torch::stack(errors), torch::stack(identity));
  std::vector<torch::Tensor> per_source;
  for (size_t i = 0; i < errors.size(); ++i)
    per_source.push_back(
        masked_mean(errors[i], loss_mask(errors[i], valids[i], cfg.automask ? identity[i] : errors[i], cfg)));
  return torch::stack(per_source).mean();
}

}  // namespace

RigidTerms rigid_terms(const LossInputs& in, const LossConfig& cfg) {
  check_shape(in.tgt, "tgt", {-1, 3, -1, -1});
  const auto B = in.tgt.size(0);
  const auto N = static_cast<int64_t>(in.srcs.size());
  const int S = static_cast<int>(in.tgt_disp.size());
  TORCH_CHECK(N >= 1, "at least one source image is needed");
  TORCH_CHECK(S >= 1, "tgt_disp must hold at least one scale");
  check_shape(in.K, "K", {B, 3, 3});
  check_shape(in.poses, "poses", {B, N, 6});
  TORCH_CHECK(static_cast<int64_t>(in.src_disp.size()) == N, "src_disp must hold ", N, " sources, got ",
              in.src_disp.size());
  for (int64_t i = 0; i < N; ++i) {
    TORCH_CHECK(in.srcs[i].sizes() == in.tgt.sizes(), "srcs[", i, "] ", in.srcs[i].sizes(), " must match tgt ",
                in.tgt.sizes());
    TORCH_CHECK(static_cast<int>(in.src_disp[i].size()) == S, "src_disp[", i, "] must hold ", S, " scales");
  }
  for (int s = 0; s < S; ++s) {
    const int64_t h = in.tgt.size(2) >> s, w = in.tgt.size(3) >> s;
    check_shape(in.tgt_disp[s], "tgt_disp[s]", {B, 1, h, w});
    for (int64_t i = 0; i < N; ++i) check_shape(in.src_disp[i][s], "src_disp[i][s]", {B, 1, h, w});
  }

  RigidTerms out;
  out.tgt_pyr = image_pyramid(to_loss_range(in.tgt, cfg), S);
  const auto Ks = intrinsics_pyramid(in.K, S);
  std::vector<torch::Tensor> rigid_per_scale, smooth_per_scale;
  for (int64_t i = 0; i < N; ++i) {
    out.src_pyr.push_back(image_pyramid(to_loss_range(in.srcs[i], cfg), S));
    for (auto* v : {&out.fwd_flow, &out.bwd_flow, &out.fwd_warp, &out.bwd_warp, &out.fwd_error, &out.bwd_error})
      v->emplace_back(S);
  }
  std::vector<torch::Tensor> src_from_tgt, tgt_from_src;
  for (int64_t i = 0; i < N; ++i) {
    src_from_tgt.push_back(pose_vec_to_matrix(in.poses.select(1, i)));
    tgt_from_src.push_back(inverse_transform(src_from_tgt.back()));
  }

  torch::Tensor rigid, smooth;
  for (int s = 0; s < S; ++s) {
    std::vector<torch::Tensor> fe, fv, fi, be, bv, bi;
    for (int64_t i = 0; i < N; ++i) {
      const auto& src = out.src_pyr[i][s];
      const auto& tgt = out.tgt_pyr[s];
      out.fwd_flow[i][s] = rigid_flow(1.0 / in.tgt_disp[s], src_from_tgt[i], Ks[s]);
      out.bwd_flow[i][s] = rigid_flow(1.0 / in.src_disp[i][s], tgt_from_src[i], Ks[s]);
      const auto fv_ = rigid_view(src, tgt, out.fwd_flow[i][s], cfg);
      const auto bv_ = rigid_view(tgt, src, out.bwd_flow[i][s], cfg);
      const Warped &fw = fv_.warp, &bw = bv_.warp;
      const torch::Tensor &fwd_channels = fv_.error_channels, &bwd_channels = bv_.error_channels;
      out.fwd_warp[i][s] = fw.image;
      out.bwd_warp[i][s] = bw.image;
      out.fwd_error[i][s] = fwd_channels.mean(1, true);
      out.bwd_error[i][s] = bwd_channels.mean(1, true);
      if (s == 0) {  // for the FlowNet's input (flow stages only take their norm)
        out.fwd_error_channels.push_back(fwd_channels);
        out.bwd_error_channels.push_back(bwd_channels);
      }
      fe.push_back(out.fwd_error[i][s]);
      fv.push_back(fw.valid);
      be.push_back(out.bwd_error[i][s]);
      bv.push_back(bw.valid);
      if (cfg.automask) {
        torch::NoGradGuard no_grad;
        fi.push_back(photometric_error(src, tgt, cfg.ssim_alpha));
        bi.push_back(photometric_error(tgt, src, cfg.ssim_alpha));
      }
    }
    torch::Tensor fwd_masked, bwd_masked;
    const auto term = direction_loss(fe, fv, fi, cfg, s == 0 ? &fwd_masked : nullptr) +
                      direction_loss(be, bv, bi, cfg, s == 0 ? &bwd_masked : nullptr);
    if (fwd_masked.defined()) out.automasked = 0.5 * (fwd_masked + bwd_masked);
    rigid = rigid.defined() ? rigid + term : term;

    std::vector<torch::Tensor> disps{in.tgt_disp[s]}, images{out.tgt_pyr[s]};
    for (int64_t i = 0; i < N; ++i) {
      disps.push_back(in.src_disp[i][s]);
      images.push_back(out.src_pyr[i][s]);
    }
    const auto sm = edge_aware_smoothness(torch::cat(disps), torch::cat(images)) / static_cast<double>(int64_t{1} << s);
    smooth = smooth.defined() ? smooth + sm : sm;
  }
  // GeoNet's factor num_source / 2 (its L_br is the mean over the sources stacked on the batch, times it).
  out.rigid = cfg.rigid_source_factor ? rigid * (static_cast<double>(N) / 2.0) : rigid;
  out.disp_smooth = smooth;
  return out;
}

FlowTerms flow_terms(const RigidTerms& rigid, const PerSourceScale<torch::Tensor>& fwd_full,
                     const PerSourceScale<torch::Tensor>& bwd_full, const LossConfig& cfg,
                     double flow_consistency_weight) {
  const size_t N = rigid.src_pyr.size();
  const int S = static_cast<int>(rigid.tgt_pyr.size());
  TORCH_CHECK(fwd_full.size() == N && bwd_full.size() == N, "full flows must hold ", N, " sources, got ",
              fwd_full.size(), " and ", bwd_full.size());
  const OutOfView sampler = out_of_view(cfg);
  const bool consistency_mask = cfg.flow_mask == FlowMask::kConsistency;
  FlowTerms out;
  out.fwd_visible.assign(N, std::vector<torch::Tensor>(S));
  out.bwd_visible.assign(N, std::vector<torch::Tensor>(S));
  std::vector<torch::Tensor> fr, fs, fg;
  const bool geonet = cfg.flow_reduction == FlowReduction::kGeoNet;
  const bool unmasked = geonet && flow_consistency_weight == 0;
  // GeoNet's reduction: per scale, the errors and masks of all sources pooled into one masked mean
  // per direction ([scale] -> per-source tensors, concatenated over the batch below).
  std::vector<std::vector<torch::Tensor>> pooled_fe(S), pooled_fm(S), pooled_be(S), pooled_bm(S);
  for (size_t i = 0; i < N; ++i) {
    TORCH_CHECK(static_cast<int>(fwd_full[i].size()) == S && static_cast<int>(bwd_full[i].size()) == S,
                "full flows of source ", i, " must hold ", S, " scales");
    for (int s = 0; s < S; ++s) {
      const auto& tgt = rigid.tgt_pyr[s];
      const auto& src = rigid.src_pyr[i][s];
      const auto& ff = fwd_full[i][s];
      const auto& bf = bwd_full[i][s];
      check_shape(ff, "fwd_full[i][s]", {tgt.size(0), 2, tgt.size(2), tgt.size(3)});
      check_shape(bf, "bwd_full[i][s]", {tgt.size(0), 2, tgt.size(2), tgt.size(3)});
      const auto bw_at_fw = backward_at_forward(ff, bf, sampler);
      const auto fw_at_bw = backward_at_forward(bf, ff, sampler);
      out.fwd_visible[i][s] = visibility_mask(ff, bw_at_fw, cfg.occ_alpha1, cfg.occ_alpha2);
      out.bwd_visible[i][s] = visibility_mask(bf, fw_at_bw, cfg.occ_alpha1, cfg.occ_alpha2);
      const auto cf =
          geometric_consistency(ff, bw_at_fw, cfg.consistency_a, cfg.consistency_b, s, cfg.consistency_scale_factor);
      const auto cb =
          geometric_consistency(bf, fw_at_bw, cfg.consistency_a, cfg.consistency_b, s, cfg.consistency_scale_factor);
      const auto fw = warp(src, ff, sampler), bw = warp(tgt, bf, sampler);
      auto fmask = consistency_mask ? cf.mask : out.fwd_visible[i][s];
      auto bmask = consistency_mask ? cb.mask : out.bwd_visible[i][s];
      if (cfg.mask_out_of_view) {
        fmask = fmask * fw.valid;
        bmask = bmask * bw.valid;
      }
      const auto fe = photometric_error(fw.image, tgt, cfg.ssim_alpha);
      const auto be = photometric_error(bw.image, src, cfg.ssim_alpha);
      if (unmasked) {
        fmask = torch::ones_like(fmask);
        bmask = torch::ones_like(bmask);
      }
      if (geonet) {
        pooled_fe[s].push_back(fe), pooled_fm[s].push_back(fmask), pooled_be[s].push_back(be),
            pooled_bm[s].push_back(bmask);
      } else {
        fr.push_back(masked_mean(fe, fmask) + masked_mean(be, bmask));
      }
      fs.push_back((edge_aware_smoothness(ff, tgt) + edge_aware_smoothness(bf, src)) /
                   static_cast<double>(int64_t{1} << (s + 1)));
      fg.push_back(0.5 * (cf.loss + cb.loss));
    }
  }
  // Sum over scales, mean over sources: the per-(source, scale) entries sum to S * N terms.
  const double n = static_cast<double>(N);
  if (geonet) {  // sum over scales of num_source / 2 x (pooled fwd + pooled bwd)
    for (int s = 0; s < S; ++s)
      fr.push_back(masked_mean(torch::cat(pooled_fe[s]), torch::cat(pooled_fm[s])) +
                   masked_mean(torch::cat(pooled_be[s]), torch::cat(pooled_bm[s])));
    out.flow = torch::stack(fr).sum() * (n / 2.0);
  } else {
    out.flow = torch::stack(fr).sum() / n;
  }
  out.flow_smooth = torch::stack(fs).sum() / n;
  out.flow_consistency = torch::stack(fg).sum() / n;
  return out;
}

LossTerms total_loss(const RigidTerms& rigid, const FlowTerms* flow, const LossWeights& w, const torch::Tensor& ground,
                     const torch::Tensor& anchor) {
  LossTerms t;
  t.rigid = rigid.rigid;
  t.disp_smooth = rigid.disp_smooth;
  t.automasked = rigid.automasked;
  t.total = w.rigid * t.rigid + w.disp_smooth * t.disp_smooth;
  if (ground.defined()) {
    t.ground = ground;
    t.total = t.total + w.ground * t.ground;
  }
  if (anchor.defined()) {
    t.anchor = anchor;
    t.total = t.total + w.anchor * t.anchor;
  }
  if (flow) {
    t.flow = flow->flow;
    t.flow_smooth = flow->flow_smooth;
    t.flow_consistency = flow->flow_consistency;
    t.total = t.total + w.flow * t.flow + w.flow_smooth * t.flow_smooth + w.flow_consistency * t.flow_consistency;
  }
  return t;
}

std::pair<std::vector<std::string>, torch::Tensor> LossTerms::stacked() const {
  std::vector<std::string> names;
  std::vector<torch::Tensor> scalars;
  for (const auto& [name, v] : {std::pair<const char*, const torch::Tensor&>{"rigid", rigid},
                                {"flow", flow},
                                {"disp_smooth", disp_smooth},
                                {"flow_smooth", flow_smooth},
                                {"flow_consistency", flow_consistency},
                                {"ground", ground},
                                {"anchor", anchor},
                                {"automasked", automasked},
                                {"total", total}})
    if (v.defined()) {
      names.emplace_back(name);
      scalars.push_back(v.detach().reshape({}).to(torch::kFloat64));
    }
  if (scalars.empty()) return {names, {}};
  return {names, torch::stack(scalars)};
}

std::vector<std::pair<std::string, double>> LossTerms::values() const {
  const auto [names, device] = stacked();
  std::vector<std::pair<std::string, double>> out;
  if (names.empty()) return out;
  const auto host = device.cpu();  // one device-to-host copy
  for (size_t i = 0; i < names.size(); ++i) out.emplace_back(names[i], host[static_cast<int64_t>(i)].item<double>());
  return out;
}

}  // namespace geo
