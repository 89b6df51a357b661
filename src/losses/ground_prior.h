// What stands on the road is not beyond it: a depth prior from the road plane (monocular training on
// traffic). A level camera at height h above a flat road sees, along pixel row v below the horizon,
// the road at depth z_road = h fy / (v - cy), whatever the column; anything standing on the road
// (a car, a pole, a wall) is in front of the road behind it, so depth <= z_road, disparity >=
// h^-1 (v - cy) / fy. A car moving with the camera explains the photometric loss equally well at
// any depth (and auto-masking leaves its pixels out); without this bound it drifts to infinite
// depth. The camera's height h is the prediction's own (the median of (v - cy) / fy x depth over the
// image's lower rows, no gradient): the term needs no camera height or scale, holds for any depth
// scale, and teaches a network that sees no road yet (a near-uniform depth map) the road's shape
// below the median row: the ground-contact idea of Dynamo-Depth (Sun & Hariharan, NeurIPS 2023)
// without its segmentation. Assumes a level camera (KITTI's and dash cams' within a degree or two)
// and a flat road covering at least half of the lower rows.
#pragma once

#include <torch/torch.h>

namespace geo {

// The lower share of the image's rows where the camera's height is measured (the road ahead).
inline constexpr double kGroundRows = 0.4;

// disp [B,1,H,W] (disparity = 1/depth, the DepthNet's finest scale), K [B,3,3] for that size.
// Returns the mean over the bounded pixels of
//   relu(1 - tolerance - disp / disp_road)
// (0 where the disparity is at least the road's; 1 - tolerance at infinite depth). Bounded: rows
// whose road lies within max_heights camera heights (the far road near the horizon bounds nothing
// useful and is where the level assumption is weakest); 0 (with a gradient path) when the lower
// rows of no image lie there.
torch::Tensor ground_prior(const torch::Tensor& disp, const torch::Tensor& K, double tolerance = 0.05,
                           double max_heights = 20.0);

}  // namespace geo
