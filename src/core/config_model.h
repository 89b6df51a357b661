// The model: section of a config (networks: ResNet depth, FR, BatchNorm convention, heads).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/config_base.h"

namespace geo {

enum class Upsample { kNearest, kBilinear };
const std::vector<EnumName<Upsample>>& enum_names(Upsample);

struct ModelConfig {
  int encoder_depth = 50;                  // ResNet-50 encoder (paper Sec. 3.1); 18/34 for speed and tests
  bool use_fr = true;                      // feature refinement on (paper); false = Table 4 "w/o FR"
  bool fr_encoder = true;                  // FR after each residual stage, Refined1..4 (paper)
  bool fr_decoder = true;                  // FR after each decoder stage, Refined5..10 (paper)
  int fr_ratio = 16;                       // channel-attention reduction ratio r (paper, CBAM)
  bool fr_spatial_bn = false;              // BatchNorm after the 7x7 spatial conv (CBAM's code; optional)
  Upsample upsample = Upsample::kNearest;  // decoder upsampling: nearest (GeoNet) or bilinear
  int num_scales = 4;                      // scales the losses use: full, 1/2, 1/4, 1/8 (GeoNet's num_scales)
  // BatchNorm of every conv+BN layer. GeoNet uses TF-slim's batch_norm: epsilon 1e-3, decay 0.999
  // (= momentum 0.001 in PyTorch's convention) and scale=False (no learned gamma). LibTorch's
  // defaults are eps 1e-5, momentum 0.1, learned gamma.
  double bn_eps = 1e-3;        // GeoNet (slim); LibTorch: 1e-5
  double bn_momentum = 0.001;  // GeoNet (slim decay 0.999); LibTorch: 0.1
  bool bn_scale = false;       // learn gamma: GeoNet false (slim scale=False); LibTorch true
  // The FlowNet's prediction convs start at zero, so stage 2 starts from stage 1's flow (the full
  // flow is the rigid flow until the residual learns); GeoNet: Xavier, a random residual of a few
  // pixels that stage 2 first has to unlearn (docs/geonet_fidelity.md).
  bool flow_zero_init = false;
  // A head on the PoseNet predicts the camera (fx, fy, cx, cy) and the rigid warp uses it instead of
  // the data's intrinsics ("Depth from Videos in the Wild", Gordon et al., ICCV 2019): for footage
  // nobody calibrated. Off: the paper and GeoNet use the calibration. On by itself for data.videos
  // without data.camera.
  bool learn_intrinsics = false;

  template <class V>
  void fields(V& v) {
    v("encoder_depth", encoder_depth);
    v("use_fr", use_fr);
    v("fr_encoder", fr_encoder);
    v("fr_decoder", fr_decoder);
    v("fr_ratio", fr_ratio);
    v("fr_spatial_bn", fr_spatial_bn);
    v("upsample", upsample);
    v("num_scales", num_scales);
    v("bn_eps", bn_eps);
    v("bn_momentum", bn_momentum);
    v("bn_scale", bn_scale);
    v("flow_zero_init", flow_zero_init);
    v("learn_intrinsics", learn_intrinsics);
  }
  void validate(Checker& c) const;
};

}  // namespace geo
