// The photometric view of a warp, shared by the losses and by inference (the FlowNet's input): the
// loss range of images, the sampler, and a source warped into the target's view with its
// per-channel error. In geo_photometric, below both geo_losses and the pipeline, so that the
// inference library does not link the losses.
#pragma once

#include <torch/torch.h>

#include "core/config.h"
#include "geometry/warp.h"

namespace geo {

// The sampler the config selects (loss.sampler: zeros -> OutOfView::kZero, border -> kBorder).
OutOfView out_of_view(const LossConfig& cfg);
// Images in [0,1] -> the range the losses see (loss.image_range), and back.
torch::Tensor to_loss_range(const torch::Tensor& image01, const LossConfig& cfg);
torch::Tensor from_loss_range(const torch::Tensor& image, const LossConfig& cfg);

// One direction of the rigid step: `src` warped into the view of `tgt` by `flow` (loss.sampler) and
// the per-channel photometric error of the warp against tgt; src and tgt in the loss range. What
// rigid_terms computes for every source and scale, and inference for the FlowNet's input.
struct RigidView {
  Warped warp;
  torch::Tensor error_channels;  // [B,3,h,w]
};
RigidView rigid_view(const torch::Tensor& src, const torch::Tensor& tgt, const torch::Tensor& flow,
                     const LossConfig& cfg);

}  // namespace geo
