// Image files through OpenCV (KITTI devkit formats): colour images, KITTI 16-bit flow PNGs and
// 16-bit depth/disparity PNGs. Every reader names the file and the problem on bad input.
#pragma once

#include <torch/torch.h>

#include <string>

namespace geo {

// RGB image -> float32 [3,H,W] in [0,1]. Grey images are expanded to 3 channels; 16-bit images
// are scaled by 1/65535. Missing or undecodable files throw std::runtime_error naming the path.
torch::Tensor read_image(const std::string& path);
// Same, resized to height x width (INTER_AREA when shrinking, linear otherwise); the original size
// is returned through `original_hw` when given.
torch::Tensor read_image_resized(const std::string& path, int64_t height, int64_t width,
                                 int64_t* original_height = nullptr, int64_t* original_width = nullptr);
// float [3,H,W] in [0,1] (or uint8) -> 8-bit PNG/JPEG by extension, written atomically.
void write_image(const std::string& path, const torch::Tensor& image);
// The same image as PNG file bytes (for TensorBoard summaries).
std::string encode_png(const torch::Tensor& image);

// KITTI flow PNG: 16-bit, 3 channels, file order R = u, G = v, B = valid; u,v = (value - 2^15)/64.
struct FlowMap {
  torch::Tensor flow;   // [2,H,W] float32, pixels (u, v)
  torch::Tensor valid;  // [1,H,W] float32 in {0,1}
};
FlowMap read_flow_png(const std::string& path);
// flow [2,H,W], valid [1,H,W] (or undefined = all valid). Values are rounded to 1/64 px and
// clamped to the format's range of +-512 px.
void write_flow_png(const std::string& path, const torch::Tensor& flow, const torch::Tensor& valid = {});

// 16-bit depth or disparity PNG: value / 256, 0 = invalid -> float32 [1,H,W].
torch::Tensor read_depth_png(const std::string& path);
// depth [1,H,W] or [H,W] in metres (0 = invalid; values above 255.99 are clamped).
void write_depth_png(const std::string& path, const torch::Tensor& depth);

// KITTI 2015 object map (obj_map/%06d_10.png): 8-bit grey, 0 = background, k > 0 = the k-th moving
// object (the devkit's foreground). Read as [H,W] uint8; written from any integer or float [H,W]
// (or [1,H,W]) with values in 0..255.
torch::Tensor read_object_map(const std::string& path);
void write_object_map(const std::string& path, const torch::Tensor& objects);

// 8-bit BGR visualisations written as PNG: disparity through a colour map, flow through the
// Middlebury colour wheel (max_flow <= 0: the image's own maximum).
torch::Tensor colorize_disparity(const torch::Tensor& disp);                  // [1,H,W] -> [3,H,W] in [0,1]
torch::Tensor colorize_flow(const torch::Tensor& flow, double max_flow = 0);  // [2,H,W] -> [3,H,W]

}  // namespace geo
