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
// RGB [3,H,W] float in [0,1] (clamped) or uint8 -> 8-bit BGR.
cv::Mat tensor_to_bgr8(const torch::Tensor& image);

}  // namespace geo
