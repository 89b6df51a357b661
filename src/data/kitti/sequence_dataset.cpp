#include "data/kitti/sequence_dataset.h"

#include "core/files.h"
#include "data/kitti/calib.h"
#include "data/image_io.h"

#include <cstdio>
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
        (e.frame_at(-half) < 0 || !std::filesystem::exists(e.image_path(options_.root, -half)) ||
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

namespace {

// Reads the frames (all the same size), resizes them to height x width and scales K to match.
Snippet load_snippet(const std::vector<std::string>& paths, const torch::Tensor& K_original, int64_t height,
                     int64_t width, std::string id) {
  std::vector<torch::Tensor> frames;
  int64_t h0 = 0, w0 = 0;
  for (size_t i = 0; i < paths.size(); ++i) {
    int64_t h = 0, w = 0;
    frames.push_back(read_image_resized(paths[i], height, width, &h, &w));
    if (i == 0) {
      h0 = h;
      w0 = w;
    } else if (h != h0 || w != w0) {
      throw std::runtime_error("image '" + paths[i] + "' is " + std::to_string(w) + "x" + std::to_string(h) +
                               " but its neighbour is " + std::to_string(w0) + "x" + std::to_string(h0));
    }
  }
  auto K = K_original.clone();
  K[0] *= static_cast<double>(width) / static_cast<double>(w0);   // fx, cx
  K[1] *= static_cast<double>(height) / static_cast<double>(h0);  // fy, cy
  return {torch::stack(frames), K.to(torch::kFloat32), std::move(id)};
}

}  // namespace

Snippet SequenceDataset::get(size_t index) const {
  const SplitEntry& e = entries_.at(index);
  const int64_t half = options_.seq_length / 2;
  std::vector<std::string> paths;
  for (int64_t o = -half; o <= half; ++o) paths.push_back(e.image_path(options_.root, o));
  return load_snippet(paths, intrinsics(e), options_.height, options_.width, e.line);
}

OdometryDataset::OdometryDataset(OdometryDatasetOptions options) : options_(std::move(options)) {
  if (options_.seq_length < 3 || options_.seq_length % 2 == 0)
    throw std::invalid_argument("seq_length must be odd and >= 3, got " + std::to_string(options_.seq_length));
  const int64_t half = options_.seq_length / 2;
  for (const auto& seq : options_.sequences) {
    const std::string dir = options_.root + "/sequences/" + seq;
    if (!std::filesystem::is_directory(dir + "/image_2"))
      throw std::runtime_error("KITTI odometry sequence " + seq + " not found: '" + dir +
                               "/image_2' is not a folder (data.root must hold sequences/XX/)");
    K_[seq] = read_odometry_calib(dir + "/calib.txt").P.at(2).slice(1, 0, 3).to(torch::kFloat64);
    int64_t n = 0;
    while (std::filesystem::exists(image_path(seq, n))) ++n;
    for (int64_t f = half; f + half < n; ++f) entries_.emplace_back(seq, f);
  }
}

std::string OdometryDataset::image_path(const std::string& sequence, int64_t frame) const {
  return options_.root + "/sequences/" + sequence + "/image_2/" + zero_padded(frame, 6) + ".png";
}

std::string OdometryDataset::id(size_t index) const {
  const auto& [seq, frame] = entries_.at(index);
  return "odometry " + seq + " " + std::to_string(frame);
}

Snippet OdometryDataset::get(size_t index) const {
  const auto& [seq, frame] = entries_.at(index);
  const int64_t half = options_.seq_length / 2;
  std::vector<std::string> paths;
  for (int64_t o = -half; o <= half; ++o) paths.push_back(image_path(seq, frame + o));
  return load_snippet(paths, K_.at(seq), options_.height, options_.width, id(index));
}

}  // namespace geo
