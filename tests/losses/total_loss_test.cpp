#include "losses/total_loss.h"

#include <gtest/gtest.h>

#include <cmath>

namespace {

// A world where the truth is known: a textured plane at depth 10 seen by a camera that moves
// 0.5 m sideways. With fx = 40 the rigid flow is exactly 2 px at scale 0 and 1 px at scale 1.
struct Scene {
  geo::LossInputs in;
  torch::Tensor true_pose;
};

Scene shifted_plane(int scales, double pose_tx) {
  torch::manual_seed(13);
  const int64_t B = 1, H = 16, W = 24;
  const auto wide = torch::rand({B, 3, H, W + 4}, torch::kFloat64);
  Scene sc;
  sc.in.tgt = wide.narrow(3, 0, W).contiguous();
  sc.in.srcs = {wide.narrow(3, 2, W).contiguous()};  // src(x) = tgt(x + 2)... shifted view
  sc.in.K = torch::tensor({40., 0., 12., 0., 40., 8., 0., 0., 1.}, torch::kFloat64).view({1, 3, 3});
  sc.in.src_disp.resize(1);
  for (int s = 0; s < scales; ++s) {
    sc.in.tgt_disp.push_back(torch::full({B, 1, H >> s, W >> s}, 0.1, torch::kFloat64));
    sc.in.src_disp[0].push_back(torch::full({B, 1, H >> s, W >> s}, 0.1, torch::kFloat64));
  }
  sc.in.poses = torch::zeros({B, 1, 6}, torch::kFloat64);
  sc.in.poses[0][0][0] = pose_tx;
  return sc;
}

TEST(TotalLoss, TruePoseReconstructsExactlyOnVisiblePixels) {
  // src(x) = wide(x + 2) and tgt(x) = wide(x): the target pixel x is seen at x - 2 in the source,
  // which is a camera translation of tx = -0.5 m (u = fx tx / Z = -2).
  geo::LossConfig cfg;
  cfg.ssim_alpha = 0.0;  // pure L1: exact per pixel
  cfg.mask_out_of_view = true;
  const auto right = geo::rigid_terms(shifted_plane(2, -0.5).in, cfg);
  EXPECT_LT(right.rigid.item<double>(), 1e-8);  // projection's z + 1e-10 (GeoNet)
  EXPECT_NEAR(right.fwd_flow[0][0][0][0][5][5].item<double>(), -2.0, 1e-9);
  EXPECT_NEAR(right.fwd_flow[0][1][0][0][5][5].item<double>(), -1.0, 1e-9);
  EXPECT_NEAR(right.bwd_flow[0][0][0][0][5][5].item<double>(), 2.0, 1e-9);
  const auto wrong = geo::rigid_terms(shifted_plane(2, 0.5).in, cfg);
  EXPECT_GT(wrong.rigid.item<double>(), 0.05);
  EXPECT_EQ(right.disp_smooth.item<double>(), 0.0);  // constant disparity
}

// min_reprojection (monodepth2): each pixel is scored by the source that explains it best. Beside
// the true shifted view (which cannot see two columns: border-sampled there, not masked here) a
// still copy of the target explains every pixel: the loss is exactly 0. Averaged over the sources,
// as GeoNet does, the two columns count. (Border sampling: GeoNet's zero sampler leaves the last
// row and column out even without motion.)
TEST(TotalLoss, MinReprojectionTakesTheBestSourcePerPixel) {
  auto sc = shifted_plane(1, -0.5);
  sc.in.srcs.push_back(sc.in.tgt.clone());
  sc.in.src_disp.push_back(sc.in.src_disp[0]);
  sc.in.poses = torch::zeros({1, 2, 6}, torch::kFloat64);
  sc.in.poses[0][0][0] = -0.5;  // the true motion to the shifted view; none to the copy
  geo::LossConfig cfg;
  cfg.ssim_alpha = 0.0;
  cfg.mask_out_of_view = false;
  cfg.sampler = geo::Sampler::kBorder;
  EXPECT_GT(geo::rigid_terms(sc.in, cfg).rigid.item<double>(), 1e-3);
  cfg.min_reprojection = true;
  EXPECT_LT(geo::rigid_terms(sc.in, cfg).rigid.item<double>(), 1e-8);
}

// automask (monodepth2): pixels that the unwarped source already matches better than the warped
// one are left out. A still scene (source = target) seen with a wrong motion: every pixel is left
// out, the loss is 0; without the mask the wrong motion costs.
TEST(TotalLoss, AutomaskLeavesOutPixelsThatTheMotionDoesNotExplain) {
  auto sc = shifted_plane(1, 0.5);
  sc.in.srcs = {sc.in.tgt.clone()};
  geo::LossConfig cfg;
  cfg.ssim_alpha = 0.0;
  cfg.mask_out_of_view = true;
  EXPECT_GT(geo::rigid_terms(sc.in, cfg).rigid.item<double>(), 0.05);
  EXPECT_FALSE(geo::rigid_terms(sc.in, cfg).automasked.defined());  // reported only when masking
  cfg.automask = true;
  const auto still = geo::rigid_terms(sc.in, cfg);
  EXPECT_EQ(still.rigid.item<double>(), 0.0);
  EXPECT_EQ(still.automasked.item<double>(), 1.0);  // every pixel left out, and reported so
  // The shifted view with its true motion: warping explains every visible pixel better than the
  // still source does, nothing is left out and the loss stays that of the true motion (~0).
  auto shifted = shifted_plane(1, -0.5);
  const auto moved = geo::rigid_terms(shifted.in, cfg);
  EXPECT_LT(moved.rigid.item<double>(), 1e-8);
  // Left out: the two columns the source cannot see (of 24) and pixels of equal colour at both.
  EXPECT_LT(moved.automasked.item<double>(), 0.2);
}

TEST(TotalLoss, ImageRangeScalesL1AndTheEdgeWeights) {
  // Pure L1 on in-view pixels: GeoNet's [-1,1] range doubles every difference.
  auto sc = shifted_plane(1, 0.5);  // the wrong pose: a non-zero error
  geo::LossConfig unit, geonet;
  unit.image_range = {0.0, 1.0};
  for (auto* c : {&unit, &geonet}) {
    c->ssim_alpha = 0.0;
    c->mask_out_of_view = true;
  }
  EXPECT_EQ(geonet.image_range, (std::vector<double>{-1.0, 1.0}));  // the default
  const double l01 = geo::rigid_terms(sc.in, unit).rigid.item<double>();
  EXPECT_GT(l01, 0.01);
  EXPECT_NEAR(geo::rigid_terms(sc.in, geonet).rigid.item<double>(), 2 * l01, 1e-12);
  // Edge weights: a column ramp 0.04 x (|dx I| = 0.04 in [0,1] units) and disparity 0.1 + 0.001 x:
  // smoothness = 0.001 exp(-0.04) on [0,1], 0.001 exp(-0.08) on [-1,1] (GeoNet's exp(-2g)).
  const auto ramp = torch::arange(24, torch::kFloat64).view({1, 1, 1, 24}).expand({1, 3, 16, 24});
  sc.in.tgt = (0.04 * ramp).contiguous();
  sc.in.srcs = {sc.in.tgt.clone()};
  const auto disp = (0.1 + 0.001 * ramp.narrow(1, 0, 1)).contiguous();
  sc.in.tgt_disp = {disp};
  sc.in.src_disp = {{disp}};
  // Mean over the W-1 column pairs of |dx d| e^{-w}, for each of the two frames: both equal.
  EXPECT_NEAR(geo::rigid_terms(sc.in, unit).disp_smooth.item<double>(), 0.001 * std::exp(-0.04), 1e-12);
  EXPECT_NEAR(geo::rigid_terms(sc.in, geonet).disp_smooth.item<double>(), 0.001 * std::exp(-0.08), 1e-12);
}

TEST(TotalLoss, RigidLossCarriesGeoNetsSourceFactor) {
  // GeoNet: L_br x num_source / 2. The same source four times (a 5-frame snippet) has the mean
  // over sources of one source; GeoNet's factor doubles it, 2 sources (3 frames) leave it as is.
  auto one = shifted_plane(2, 0.5).in;
  geo::LossConfig off, geonet;
  off.rigid_source_factor = false;
  EXPECT_TRUE(geonet.rigid_source_factor);  // the default
  const double single = geo::rigid_terms(one, off).rigid.item<double>();
  EXPECT_GT(single, 0.01);
  auto sources = [&](int n) {
    auto in = one;
    in.srcs.assign(n, one.srcs[0]);
    in.src_disp.assign(n, one.src_disp[0]);
    in.poses = one.poses.repeat({1, n, 1});
    return in;
  };
  EXPECT_NEAR(geo::rigid_terms(sources(4), off).rigid.item<double>(), single, 1e-12);
  EXPECT_NEAR(geo::rigid_terms(sources(4), geonet).rigid.item<double>(), 2 * single, 1e-12);
  EXPECT_NEAR(geo::rigid_terms(sources(2), geonet).rigid.item<double>(), single, 1e-12);
  EXPECT_NEAR(geo::rigid_terms(sources(1), geonet).rigid.item<double>(), 0.5 * single, 1e-12);
  // The smoothness term has no such factor.
  EXPECT_NEAR(geo::rigid_terms(sources(4), geonet).disp_smooth.item<double>(),
              geo::rigid_terms(sources(4), off).disp_smooth.item<double>(), 1e-15);
}

// Forward flow u = 1 on an 8x8 image; the backward flow disagrees by 2.5 px on a 2x2 block (rows
// 2-3, columns 4-5), where the source is 1 and everything else 0.
struct DisputedBlock {
  torch::Tensor zeros, ff, bf, src;
};
DisputedBlock disputed_block() {
  const int64_t H = 8, W = 8;
  DisputedBlock d;
  d.zeros = torch::zeros({1, 3, H, W}, torch::kFloat64);
  d.ff = torch::zeros({1, 2, H, W}, torch::kFloat64);
  d.ff.select(1, 0).fill_(1.0);
  d.bf = -d.ff.clone();
  d.bf.select(1, 0).narrow(1, 2, 2).narrow(2, 4, 2).fill_(1.5);
  d.src = d.zeros.clone();
  d.src.narrow(2, 2, 2).narrow(3, 4, 2).fill_(1.0);
  return d;
}

TEST(TotalLoss, FlowReconstructionMaskIsEq13OrGeoNetsConsistencyMask) {
  // Forward flow u = 1; the backward flow disagrees by 2.5 px on a 2x2 block. Eq. 13 calls those
  // pixels occluded (6.25 > 0.01 (1 + 2.25) + 0.5), GeoNet's consistency bound max(3, 0.05) keeps
  // them. With an error of 1 only on those pixels, L_fr is 0 with the eq. 13 mask and
  // (4 / 64) per direction with the consistency mask.
  // The target is 0; the source is 1 on the block. Forward, target pixels x in {3, 4} read the
  // source block at x + 1: error 1 exactly where the flows disagree. Backward, the block pixels
  // read the target (0) and compare with their own 1: error 1 there too.
  const auto [zeros, ff, bf, src] = disputed_block();
  geo::RigidTerms rigid;
  rigid.tgt_pyr = {zeros};
  rigid.src_pyr = {{src}};
  geo::LossConfig cfg;
  cfg.ssim_alpha = 0.0;
  cfg.image_range = {0.0, 1.0};  // the images above are already in the loss range
  cfg.sampler = geo::Sampler::kBorder;
  const auto occ = geo::flow_terms(rigid, {{ff}}, {{bf}}, cfg);
  cfg.flow_mask = geo::FlowMask::kConsistency;
  const auto con = geo::flow_terms(rigid, {{ff}}, {{bf}}, cfg);
  EXPECT_EQ(occ.fwd_visible[0][0].sum().item<double>(), 60);
  // Each direction: error 1 on the 4 disputed pixels, excluded by eq. 13 (-> 0), kept by the
  // consistency mask (-> 4 / 64, every pixel within the bound).
  EXPECT_NEAR(occ.flow.item<double>(), 0.0, 1e-12);
  EXPECT_NEAR(con.flow.item<double>(), 4.0 / 64 + 4.0 / 64, 1e-12);
}

// loss.flow_reduction geonet: GeoNet's build_losses pools all sources into one masked mean per
// direction and scale, times num_source / 2, and leaves L_fr unmasked when l_fg is 0. Four
// sources: three with zero flow and zero error, the fourth the disputed block above (error 1 on 4
// pixels per direction, kept by the consistency mask, excluded by eq. 13).
TEST(TotalLoss, GeoNetsFlowReductionPoolsSourcesAndDropsTheMaskWithoutConsistency) {
  const auto [zeros, ff, bf, block] = disputed_block();
  geo::RigidTerms rigid;
  rigid.tgt_pyr = {zeros};
  rigid.src_pyr = {{zeros}, {zeros}, {zeros}, {block}};
  const auto still = torch::zeros_like(ff);
  const geo::PerSourceScale<torch::Tensor> fwd = {{still}, {still}, {still}, {ff}},
                                           bwd = {{still}, {still}, {still}, {bf}};
  geo::LossConfig cfg;
  cfg.ssim_alpha = 0.0;
  cfg.image_range = {0.0, 1.0};
  cfg.sampler = geo::Sampler::kBorder;
  cfg.flow_mask = geo::FlowMask::kConsistency;
  // Per source: (4/64 + 4/64) for the fourth, 0 for the others, mean over 4 sources.
  EXPECT_NEAR(geo::flow_terms(rigid, fwd, bwd, cfg).flow.item<double>(), 0.125 / 4, 1e-12);
  // GeoNet: 4 error pixels of 4 x 64 pooled per direction, (4/256 + 4/256) x num_source / 2 = 2.
  cfg.flow_reduction = geo::FlowReduction::kGeoNet;
  EXPECT_NEAR(geo::flow_terms(rigid, fwd, bwd, cfg, 0.2).flow.item<double>(), 8.0 / 256 * 2, 1e-12);
  // With the eq. 13 mask the disputed pixels are out (0); without l_fg GeoNet masks nothing.
  cfg.flow_mask = geo::FlowMask::kOcclusion;
  EXPECT_NEAR(geo::flow_terms(rigid, fwd, bwd, cfg, 0.2).flow.item<double>(), 0.0, 1e-12);
  EXPECT_NEAR(geo::flow_terms(rigid, fwd, bwd, cfg, 0.0).flow.item<double>(), 8.0 / 256 * 2, 1e-12);
  cfg.flow_reduction = geo::FlowReduction::kPerSource;  // geo's own reduction always masks
  EXPECT_NEAR(geo::flow_terms(rigid, fwd, bwd, cfg, 0.0).flow.item<double>(), 0.0, 1e-12);
}

TEST(TotalLoss, StagesWithoutFlowLeaveFlowTermsUndefined) {
  const auto sc = shifted_plane(2, -0.5);
  const geo::LossConfig cfg;
  const auto rigid = geo::rigid_terms(sc.in, cfg);
  geo::LossWeights w;
  const auto t = geo::total_loss(rigid, nullptr, w);
  EXPECT_FALSE(t.flow.defined());
  EXPECT_FALSE(t.flow_consistency.defined());
  const auto values = t.values();
  ASSERT_EQ(values.size(), 3u);  // rigid, disp_smooth, total
  EXPECT_EQ(values[0].first, "rigid");
  EXPECT_EQ(values[2].first, "total");
  EXPECT_NEAR(t.total.item<double>(),
              w.rigid * rigid.rigid.item<double>() + w.disp_smooth * rigid.disp_smooth.item<double>(), 1e-12);
}

TEST(TotalLoss, EveryTermBackPropagatesIntoDepthPoseAndFlow) {
  torch::manual_seed(14);
  const int64_t B = 2, H = 16, W = 24, N = 2, S = 3;
  geo::LossInputs in;
  in.tgt = torch::rand({B, 3, H, W}, torch::kFloat64);
  in.srcs = {torch::rand({B, 3, H, W}, torch::kFloat64), torch::rand({B, 3, H, W}, torch::kFloat64)};
  in.K = torch::tensor({20., 0., 12., 0., 20., 8., 0., 0., 1.}, torch::kFloat64).view({1, 3, 3}).repeat({B, 1, 1});
  std::vector<torch::Tensor> leaves;
  auto leaf = [&](torch::Tensor t) {
    t.requires_grad_();
    leaves.push_back(t);
    return t;
  };
  in.src_disp.resize(N);
  for (int s = 0; s < S; ++s) {
    in.tgt_disp.push_back(leaf(torch::rand({B, 1, H >> s, W >> s}, torch::kFloat64) + 0.1));
    for (int i = 0; i < N; ++i)
      in.src_disp[i].push_back(leaf(torch::rand({B, 1, H >> s, W >> s}, torch::kFloat64) + 0.1));
  }
  in.poses = leaf(torch::randn({B, N, 6}, torch::kFloat64) * 0.05);
  geo::LossConfig cfg;
  cfg.automask = true;
  cfg.min_reprojection = true;
  const auto rigid = geo::rigid_terms(in, cfg);
  geo::PerSourceScale<torch::Tensor> fwd(N), bwd(N);
  for (int i = 0; i < N; ++i)
    for (int s = 0; s < S; ++s) {
      fwd[i].push_back(rigid.fwd_flow[i][s] + leaf(torch::randn({B, 2, H >> s, W >> s}, torch::kFloat64) * 0.1));
      bwd[i].push_back(rigid.bwd_flow[i][s] + leaf(torch::randn({B, 2, H >> s, W >> s}, torch::kFloat64) * 0.1));
    }
  const auto flow = geo::flow_terms(rigid, fwd, bwd, cfg);
  const auto t = geo::total_loss(rigid, &flow, geo::LossWeights{});
  EXPECT_EQ(t.values().size(), 7u);  // five terms, the auto-masked share and the total
  EXPECT_EQ(t.values()[5].first, "automasked");
  EXPECT_EQ(t.values()[6].first, "total");
  for (const auto& term : {t.rigid, t.flow, t.disp_smooth, t.flow_smooth, t.flow_consistency}) {
    for (auto& l : leaves)
      if (l.grad().defined()) l.grad().zero_();
    term.backward({}, /*retain_graph=*/true);
    bool any = false;
    for (auto& l : leaves) {
      if (!l.grad().defined()) continue;
      EXPECT_TRUE(torch::isfinite(l.grad()).all().item<bool>());
      any = any || l.grad().abs().sum().item<double>() > 0;
    }
    EXPECT_TRUE(any);
  }
  // The pose and every depth scale get gradient from the total.
  for (auto& l : leaves)
    if (l.grad().defined()) l.grad().zero_();
  t.total.backward();
  EXPECT_GT(in.poses.grad().abs().sum().item<double>(), 0);
  for (int s = 0; s < S; ++s) EXPECT_GT(in.tgt_disp[s].grad().abs().sum().item<double>(), 0);
}

TEST(TotalLoss, MalformedInputsNameTheArgument) {
  auto sc = shifted_plane(2, 0.0);
  sc.in.poses = torch::zeros({1, 2, 6}, torch::kFloat64);  // two poses for one source
  try {
    geo::rigid_terms(sc.in, geo::LossConfig{});
    FAIL();
  } catch (const c10::Error& e) {
    EXPECT_NE(std::string(e.what_without_backtrace()).find("poses must have shape [1, 1, 6]"), std::string::npos)
        << e.what_without_backtrace();
  }
  sc = shifted_plane(2, 0.0);
  sc.in.tgt_disp[1] = torch::zeros({1, 1, 5, 5}, torch::kFloat64);
  EXPECT_THROW(geo::rigid_terms(sc.in, geo::LossConfig{}), c10::Error);
}

}  // namespace
