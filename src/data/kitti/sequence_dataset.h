// KITTI raw snippets from a split list (paper Sec. 4.2; KITTI raw, Eigen split): for each "folder frame side" entry,
// frames frame - L/2 .. frame + L/2 of camera 02 (l) or 03 (r), resized to the training size, with
// P_rect's intrinsics scaled to match. Entries without both neighbours on disk are dropped (and
// counted); test scenes and static frames can be excluded (splits.h). Needs OpenCV.
#pragma once

#include "data/snippets.h"
#include "data/kitti/splits.h"

#include <map>
#include <mutex>
#include <utility>
#include <vector>

namespace geo {

struct SequenceDatasetOptions {
  std::string root;  // KITTI raw root (holds <date>/<drive>/...)
  int64_t height = 128, width = 416, seq_length = 3;
  bool check_neighbours = true;  // drop entries whose first or last frame is missing
};

class SequenceDataset : public SnippetSource {
 public:
  SequenceDataset(std::vector<SplitEntry> entries, SequenceDatasetOptions options);
  size_t size() const override { return entries_.size(); }
  Snippet get(size_t index) const override;
  std::string id(size_t index) const override { return entries_.at(index).line; }
  int64_t seq_length() const override { return options_.seq_length; }
  size_t dropped() const { return dropped_; }
  const SplitEntry& entry(size_t index) const { return entries_.at(index); }

 private:
  torch::Tensor intrinsics(const SplitEntry& e) const;  // [3,3] float64 at the original size
  std::vector<SplitEntry> entries_;
  SequenceDatasetOptions options_;
  size_t dropped_ = 0;
  mutable std::mutex mutex_;
  mutable std::map<std::string, torch::Tensor> calib_cache_;  // "date camera" -> K
};

// KITTI odometry snippets (GeoNet trains its pose network on sequences 00-08): every frame of
// <root>/sequences/XX/image_2/%06d.png with L/2 neighbours on both sides, intrinsics from P2 of
// sequences/XX/calib.txt. Missing sequences are an error naming the folder. Needs OpenCV.
struct OdometryDatasetOptions {
  std::string root;  // holds sequences/XX/
  std::vector<std::string> sequences = {"00", "01", "02", "03", "04", "05", "06", "07", "08"};
  int64_t height = 128, width = 416, seq_length = 5;  // GeoNet's odometry model: 5-frame snippets
};

class OdometryDataset : public SnippetSource {
 public:
  explicit OdometryDataset(OdometryDatasetOptions options);
  size_t size() const override { return entries_.size(); }
  Snippet get(size_t index) const override;
  std::string id(size_t index) const override;
  int64_t seq_length() const override { return options_.seq_length; }

 private:
  std::string image_path(const std::string& sequence, int64_t frame) const;
  OdometryDatasetOptions options_;
  std::vector<std::pair<std::string, int64_t>> entries_;  // (sequence, target frame)
  std::map<std::string, torch::Tensor> K_;                // sequence -> [3,3] at the original size
};

}  // namespace geo
