// OpenCV images <-> tensors, for geo's OpenCV readers and writers (not part of the library's API).
#pragma once

#include <opencv2/core.hpp>
#include <torch/torch.h>

#include <string>

namespace geo {

// 1-, 3- or 4-channel BGR(A) 8- or 16-bit image -> float32 RGB [3,H,W] in [0,1]; `path` names it in errors.
torch::Tensor mat_to_tensor(const cv::Mat& bgr_any, const std::string& path);
// A decoded image resized to height x width as read_image_resized does (INTER_AREA when shrinking,
// linear otherwise), then as mat_to_tensor.
torch::Tensor resized_mat_to_tensor(const cv::Mat& bgr_any, int64_t height, int64_t width, const std::string& path);
// resized_mat_to_tensor as compact as the image allows: uint8 RGB [3,H,W] (0..255, what geo::Model
// takes as it is, a quarter of float's memory) for an 8-bit image, float [0,1] for a deeper one.
torch::Tensor resized_mat_to_frame(const cv::Mat& bgr_any, int64_t height, int64_t width, const std::string& path);
// RGB [3,H,W] float in [0,1] (clamped) or uint8 -> 8-bit BGR.
cv::Mat tensor_to_bgr8(const torch::Tensor& image);

}  // namespace geo
