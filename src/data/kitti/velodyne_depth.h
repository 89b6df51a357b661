// Ground-truth depth from a Velodyne scan with the Eigen protocol (Eigen et al. 2014 as in GeoNet's kitti_eval), as used by
// SfMLearner, GeoNet and monodepth2: x_img = P_rect * R_rect_00 * [R|T]_velo_to_cam * x_velo,
// points behind the scanner (x < 0) dropped, depth = the Velodyne x (forward distance), pixel =
// round(x/z) - 1 (the MATLAB-origin convention of the reference code), the nearest point kept where
// several land on one pixel.
#pragma once

#include <torch/torch.h>

namespace geo {

struct VelodyneDepthOptions {
  bool matlab_offset = true;    // subtract 1 after rounding (reference code); false = exact pixel
  bool depth_is_velo_x = true;  // depth = Velodyne x (reference code); false = camera z
};

// points [N,4] float32 (x,y,z,r), img_from_velo [3,4] -> depth [H,W] float32, 0 where no point.
// Points with a non-finite x, y or z are ignored (count_non_finite_points says how many).
torch::Tensor velodyne_depth(const torch::Tensor& points, const torch::Tensor& img_from_velo, int64_t height,
                             int64_t width, VelodyneDepthOptions options = {});

// Points [N,4] whose x, y or z is NaN or infinite.
int64_t count_non_finite_points(const torch::Tensor& points);

}  // namespace geo
