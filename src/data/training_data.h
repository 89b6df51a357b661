// Resolves the training and validation data of a config (paper Sec. 4.2; KITTI raw, Eigen split).
// data.split selects the data of a task: eigen_zhou (depth, the paper's), kitti_raw_stereo (flow,
// GeoNet's: every raw drive on disk without the 29 KITTI 2015 scenes of stereo/test_scenes_stereo.txt,
// both cameras), raw_minus_kitti2015 (the eigen_zhou lists without those scenes) or odometry (pose,
// GeoNet's: KITTI odometry data.sequences, 00-08). Shared by geo_train, geo_prepare and geo_bench.
//   data.format auto   -> a packed cache when <root>/train/index.txt is one (geo_prepare), else KITTI raw
//   kitti_raw lists    -> data.train_list / data.val_list, else <root>/splits/<split>/{train,val}_files.txt
//                         (a geo_synth world ships its own), else configs/splits/<split>/...
//   exclusions         -> test scenes (<root>/splits/eigen/test_scenes.txt or the shipped list) and
//                         the shipped static_frames.txt
// Errors name the config key (data.root, data.train_list) and the path.
#pragma once

#include "core/config.h"
#include "data/kitti/splits.h"
#include "data/snippets.h"

#include <memory>
#include <string>
#include <vector>

namespace geo {

struct TrainingData {
  std::shared_ptr<SnippetSource> train, val;  // val may be null (no validation list)
  std::string root;                           // data.root, or its raw/ for a geo_synth --out folder
  std::string format, train_list, val_list;
  size_t excluded = 0, dropped = 0;       // test-scene/static entries, entries without neighbours
  std::vector<std::string> exclusions;    // the lists that excluded entries (for the log)
  std::vector<std::string> clip_records;  // data.videos: a line per clip (VideoData::records)
};

TrainingData open_training_data(const DataConfig& data);

// Packs `data`'s training and validation snippets (of `config`'s size and sequence length) into a
// cache at `out` (train/, val/; data/packed/packed.h) that training reads with data.root=`out`, with
// progress lines. A val/ an earlier cache left there is removed when `data` has no validation set
// (returns true then).
bool write_packed_cache(const TrainingData& data, const DataConfig& config, const std::string& out);

}  // namespace geo
