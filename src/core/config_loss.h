// The loss: section of a config (the terms' constants and conventions; weights are per stage).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/config_base.h"

namespace geo {

enum class Sampler { kZeros, kBorder };
enum class FlowMask { kOcclusion, kConsistency };
enum class FlowReduction { kPerSource, kGeoNet };
const std::vector<EnumName<Sampler>>& enum_names(Sampler);
const std::vector<EnumName<FlowMask>>& enum_names(FlowMask);
const std::vector<EnumName<FlowReduction>>& enum_names(FlowReduction);

struct LossConfig {
  double ssim_alpha = 0.85;              // alpha*(1-SSIM)/2 + (1-alpha)*L1 (paper, GeoNet)
  double occ_alpha1 = 0.01;              // occlusion test, eq. 13 alpha1 (paper)
  double occ_alpha2 = 0.5;               // occlusion test, eq. 13 alpha2 (paper)
  double consistency_a = 3.0;            // geometric consistency bound a (eq. 15, GeoNet alpha)
  double consistency_b = 0.05;           // geometric consistency bound b (eq. 15, GeoNet beta)
  bool consistency_scale_factor = true;  // GeoNet multiplies the difference norm by 2^s
  // Range the images are mapped to before the photometric error, the smoothness edge weights and
  // the FlowNet's error channel: GeoNet computes them on its [-1,1] network input (so its L1 term
  // is twice the [0,1] one and its edge weights are exp(-2|grad I|) in [0,1] units); [0, 1] as
  // monodepth2.
  std::vector<double> image_range = {-1.0, 1.0};
  // Out-of-view samples of every warp: zeros (GeoNet's bilinear_sampler returns 0 outside
  // [0,W-1)x[0,H-1)) or border (clamped to the edge pixels).
  Sampler sampler = Sampler::kZeros;
  bool mask_out_of_view = false;  // drop samples that leave the image from L_br and L_fr (off: GeoNet)
  // Mask of the flow reconstruction L_fr: occlusion (paper eq. 13, alpha1/alpha2) or consistency
  // (GeoNet: the eq. 15 mask, consistency_a/consistency_b).
  FlowMask flow_mask = FlowMask::kOcclusion;
  // How L_fr averages over sources: per_source (the masked mean of each source, then the mean over
  // sources: one bad source cannot dominate) or geonet (GeoNet's build_losses: one masked mean over
  // all sources pooled, times num_source / 2, and no mask at all when the stage's l_fg is 0).
  FlowReduction flow_reduction = FlowReduction::kPerSource;
  bool min_reprojection = false;  // per-pixel minimum over sources (monodepth2; off)
  bool automask = false;          // auto-mask static pixels (monodepth2; off)
  // GeoNet's L_br carries a factor num_source / 2 (geonet_model.py: build_losses): 1 for 3-frame
  // snippets, 2 for the 5-frame odometry snippets, where it weighs L_br twice against L_ds.
  bool rigid_source_factor = true;
  // The FlowNet's inputs (rigid flow, rigid warp, its error) keep their gradient in stages that train
  // depth or pose with the flow (GeoNet's graph: L_fr, L_fs and L_fg reach the DepthNet and PoseNet
  // through them as well as through the rigid flow added to the residual); false: computed without.
  bool flow_input_gradient = true;

  template <class V>
  void fields(V& v) {
    v("ssim_alpha", ssim_alpha);
    v("occ_alpha1", occ_alpha1);
    v("occ_alpha2", occ_alpha2);
    v("consistency_a", consistency_a);
    v("consistency_b", consistency_b);
    v("consistency_scale_factor", consistency_scale_factor);
    v("image_range", image_range);
    v("sampler", sampler);
    v("mask_out_of_view", mask_out_of_view);
    v("flow_mask", flow_mask);
    v("flow_reduction", flow_reduction);
    v("min_reprojection", min_reprojection);
    v("automask", automask);
    v("rigid_source_factor", rigid_source_factor);
    v("flow_input_gradient", flow_input_gradient);
  }
  void validate(Checker& c) const;
};

}  // namespace geo
