#include "data/sequence_dataset.h"

#include "data/calib.h"
#include "data/image_io.h"

#include <filesystem>
#include <stdexcept>

namespace geo {

SequenceDataset::SequenceDataset(std::vector<SplitEntry> entries, SequenceDatasetOptions options)
    : options_(std::move(options)) {
  if (options_.seq_length < 2 || options_.seq_length % 2 == 0)
    throw std::invalid_argument("seq_length must be odd and >= 3, got " + std::to_string(options_.seq_length));
  const int64_t half = options_.seq_length / 2;
  for (auto& e : entries) {
    if (options_.check_neighbours &&
        (e.frame - half < 0 || !std::filesystem::exists(e.image_path(options_.root, -half)) ||
         !std::filesystem::exists(e.image_path(options_.root, half)))) {
      ++dropped_;
      continue;
    }
    entries_.push_back(std::move(e));
  }
}

torch::Tensor SequenceDataset::intrinsics(const SplitEntry& e) const {
  const std::string key = e.date() + " " + std::to_string(e.camera());
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = calib_cache_.find(key);
  if (it == calib_cache_.end())
    it = calib_cache_.emplace(key, read_raw_calib(options_.root + "/" + e.date(), e.camera(), false).K()).first;
  return it->second;
}

Snippet SequenceDataset::get(size_t index) const {
  const SplitEntry& e = entries_.at(index);
  const int64_t half = options_.seq_length / 2;
  std::vector<torch::Tensor> frames;
  int64_t h0 = 0, w0 = 0;
  for (int64_t o = -half; o <= half; ++o) {
    int64_t h = 0, w = 0;
    frames.push_back(read_image_resized(e.image_path(options_.root, o), options_.height, options_.width, &h, &w));
    if (o == -half) {
      h0 = h;
      w0 = w;
    } else if (h != h0 || w != w0) {
      throw std::runtime_error("image '" + e.image_path(options_.root, o) + "' is " +
                               std::to_string(w) + "x" + std::to_string(h) + " but its neighbour is " +
                               std::to_string(w0) + "x" + std::to_string(h0));
    }
  }
  auto K = intrinsics(e).clone();
  K[0] *= static_cast<double>(options_.width) / static_cast<double>(w0);   // fx, cx
  K[1] *= static_cast<double>(options_.height) / static_cast<double>(h0);  // fy, cy
  return {torch::stack(frames), K.to(torch::kFloat32), e.line};
}

}  // namespace geo
