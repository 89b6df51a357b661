// The unsupervised objective of the paper (eq. 16, paper Sec. 3.3-3.6), in two steps so that the
// FlowNet can be fed from the rigid step: rigid_terms() (L_br, L_ds, and the rigid flows / warps /
// errors the FlowNet takes as input), then flow_terms() (L_fr, L_fs, L_fg) from the full flows.
// Each warp is computed once per direction, source and scale and reused by every term.
#pragma once

#include <torch/torch.h>

#include <string>
#include <utility>
#include <vector>

#include "core/config.h"
#include "geometry/warp.h"
#include "losses/rigid_view.h"

namespace geo {

template <class T>
using PerSourceScale = std::vector<std::vector<T>>;  // [source][scale]

struct LossInputs {
  torch::Tensor tgt;                       // [B,3,H,W], RGB in [0,1]
  std::vector<torch::Tensor> srcs;         // N x [B,3,H,W]
  torch::Tensor K;                         // [B,3,3] intrinsics at full resolution
  std::vector<torch::Tensor> tgt_disp;     // S x [B,1,H>>s,W>>s], disparity (1/depth)
  PerSourceScale<torch::Tensor> src_disp;  // N x S, same shapes (for the backward direction)
  torch::Tensor poses;                     // [B,N,6] pose vectors src_from_tgt (pose.h)
};

// Images in RigidTerms are in the loss range (loss.image_range), not [0,1].
struct RigidTerms {
  std::vector<torch::Tensor> tgt_pyr;       // S: target image per scale
  PerSourceScale<torch::Tensor> src_pyr;    // source images per scale
  PerSourceScale<torch::Tensor> fwd_flow;   // rigid flow target -> source [B,2,h,w]
  PerSourceScale<torch::Tensor> bwd_flow;   // rigid flow source -> target
  PerSourceScale<torch::Tensor> fwd_warp;   // source warped into the target view
  PerSourceScale<torch::Tensor> bwd_warp;   // target warped into the source view
  PerSourceScale<torch::Tensor> fwd_error;  // photometric error maps [B,1,h,w]
  PerSourceScale<torch::Tensor> bwd_error;
  std::vector<torch::Tensor> fwd_error_channels;  // N: the full-scale per-channel error [B,3,H,W]
  std::vector<torch::Tensor> bwd_error_channels;  //    (its L2 norm is the FlowNet's input)
  // L_br: sum over scales of (fwd + bwd) masked means, mean over sources, times num_source / 2
  // (loss.rigid_source_factor, GeoNet's).
  torch::Tensor rigid;
  torch::Tensor disp_smooth;  // L_ds: sum over scales of smoothness / 2^s over all frames
  torch::Tensor automasked;   // loss.automask: the share of full-scale pixels a still frame explains
                              // better (left out; mean of both directions; no gradient), else undefined
};

// Computes L_br and L_ds. Throws on inconsistent shapes, naming the argument.
RigidTerms rigid_terms(const LossInputs& in, const LossConfig& cfg);

struct FlowTerms {
  PerSourceScale<torch::Tensor> fwd_visible;  // eq. 13 masks [B,1,h,w]
  PerSourceScale<torch::Tensor> bwd_visible;
  torch::Tensor flow;              // L_fr: full-flow reconstruction on loss.flow_mask pixels
  torch::Tensor flow_smooth;       // L_fs: smoothness of the full flows / 2^(s+1)
  torch::Tensor flow_consistency;  // L_fg: geometric consistency, mean of both directions
};

// fwd_full / bwd_full: N x S full flows (residual + rigid) in pixels of their scale.
// flow_consistency_weight: the stage's l_fg; with loss.flow_reduction geonet, 0 leaves L_fr unmasked
// (GeoNet computes its masks only for the consistency term).
FlowTerms flow_terms(const RigidTerms& rigid, const PerSourceScale<torch::Tensor>& fwd_full,
                     const PerSourceScale<torch::Tensor>& bwd_full, const LossConfig& cfg,
                     double flow_consistency_weight = 1.0);

struct LossTerms {
  // Unweighted terms; undefined when the stage does not compute them (never zero-filled).
  torch::Tensor rigid, flow, disp_smooth, flow_smooth, flow_consistency, ground, anchor;
  torch::Tensor total;       // eq. 16: the weighted sum of the defined terms
  torch::Tensor automasked;  // not a loss: RigidTerms::automasked, reported beside the terms

  // (name, value) of every defined term, the auto-masked share when defined, and the total last, for
  // logging (one device-to-host copy of stacked()).
  std::vector<std::pair<std::string, double>> values() const;
  // The same on the device, without reading it: their names, and the values as one float64 vector
  // (undefined when no term is defined).
  std::pair<std::vector<std::string>, torch::Tensor> stacked() const;
};

// Eq. 16. `flow` may be null (stages that do not train flow): flow terms are then left undefined.
// `ground`: the road-plane prior (ground_prior.h), added with weights.ground when defined; `anchor`:
// the depth anchor (depth_anchor.h), added with weights.anchor when defined.
LossTerms total_loss(const RigidTerms& rigid, const FlowTerms* flow, const LossWeights& weights,
                     const torch::Tensor& ground = {}, const torch::Tensor& anchor = {});

}  // namespace geo
