#include "train/data_source.h"

#include "data/packed.h"
#include "data/sequence_dataset.h"
#include "data/splits.h"

#include <spdlog/spdlog.h>

#include <filesystem>

namespace fs = std::filesystem;

namespace geo {

std::string find_split_file(const std::string& root, const std::string& split, const std::string& file) {
  for (const auto& base : {root + "/splits", shipped_config_dir() + "/splits"}) {
    const std::string p = base + "/" + split + "/" + file;
    if (fs::exists(p)) return p;
  }
  return "";
}

TrainingData open_training_data(const DataConfig& d) {
  if (d.root.empty())
    throw ConfigError("data.root is empty: set it in the config or with --set data.root=DIR "
                      "(a KITTI raw folder, a geo_prepare cache or a geo_synth world's raw/ folder)");
  if (!fs::is_directory(d.root))
    throw ConfigError("data.root '" + d.root + "' is not a directory");
  TrainingData out;
  const bool packed = d.format == "packed" || (d.format == "auto" && is_packed_cache(d.root + "/train"));
  if (packed) {
    out.format = "packed";
    auto train = std::make_shared<PackedSnippets>(d.root + "/train");
    if (train->height() != d.height || train->width() != d.width || train->seq_length() != d.seq_length)
      throw ConfigError("packed cache '" + d.root + "' holds " + std::to_string(train->seq_length()) +
                        "-frame snippets at " + std::to_string(train->width()) + "x" +
                        std::to_string(train->height()) + " but data.width/height/seq_length ask for " +
                        std::to_string(d.seq_length) + " frames at " + std::to_string(d.width) + "x" +
                        std::to_string(d.height) + " (re-run geo_prepare)");
    out.train = train;
    if (is_packed_cache(d.root + "/val")) out.val = std::make_shared<PackedSnippets>(d.root + "/val");
    out.train_list = d.root + "/train";
    return out;
  }
  out.format = "kitti_raw";
  out.train_list = d.train_list.empty() ? find_split_file(d.root, d.split, "train_files.txt") : d.train_list;
  out.val_list = d.val_list.empty() ? find_split_file(d.root, d.split, "val_files.txt") : d.val_list;
  if (out.train_list.empty() || !fs::exists(out.train_list))
    throw ConfigError("data.train_list: no training list found (" +
                      (d.train_list.empty() ? "looked for " + d.root + "/splits/" + d.split +
                                                  "/train_files.txt and the shipped configs/splits/" + d.split
                                            : "'" + d.train_list + "' does not exist") + ")");
  std::set<std::string> scenes, statics;
  const std::string scenes_file = find_split_file(d.root, "eigen", "test_scenes.txt");
  if (!scenes_file.empty()) scenes = read_scene_list(scenes_file);
  const std::string static_file = shipped_config_dir() + "/splits/static_frames.txt";
  if (fs::exists(static_file)) statics = read_static_frames(static_file);
  SequenceDatasetOptions so;
  so.root = d.root;
  so.height = d.height;
  so.width = d.width;
  so.seq_length = d.seq_length;
  auto entries = read_split(out.train_list);
  out.excluded = exclude_entries(entries, scenes, statics);
  auto train = std::make_shared<SequenceDataset>(std::move(entries), so);
  out.dropped = train->dropped();
  if (train->size() == 0)
    throw ConfigError("data.root '" + d.root + "': none of the " + std::to_string(out.dropped) +
                      " entries of " + out.train_list + " has its frames on disk (first missing: " +
                      read_split(out.train_list).front().image_path(d.root) + ")");
  out.train = train;
  if (!out.val_list.empty() && fs::exists(out.val_list)) {
    auto val = std::make_shared<SequenceDataset>(read_split(out.val_list), so);
    if (val->size() > 0) out.val = val;
  }
  return out;
}

}  // namespace geo
