// Edge-aware first-order smoothness (paper Sec. 3.3-3.6; GeoNet's compute_smooth_loss).
#pragma once

#include <torch/torch.h>

namespace geo {

// For each channel c of `map` [B,C,H,W] with the image [B,3,H,W] at the same size:
//   mean(|dx m_c| * exp(-mean_ch |dx I|)) + mean(|dy m_c| * exp(-mean_ch |dy I|)),
// averaged over channels (disparity: C = 1, GeoNet's compute_smooth_loss; flow: the mean of the
// u and v terms, GeoNet's compute_flow_smooth_loss divides their sum by 2).
// dx is the difference of horizontal neighbours (W-1 columns), dy of vertical ones (H-1 rows).
torch::Tensor edge_aware_smoothness(const torch::Tensor& map, const torch::Tensor& image);

}  // namespace geo
