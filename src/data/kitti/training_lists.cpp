#include "data/kitti/training_lists.h"

#include "data/packed/packed.h"
#include "data/kitti/splits.h"

#include <cctype>
#include <filesystem>

namespace fs = std::filesystem;

namespace geo {

RawTrainingLists raw_training_lists(const DataConfig& d, const std::string& root) {
  // kitti_raw_stereo (GeoNet's flow data): every drive on disk without the KITTI 2015 scenes (and
  // eigen_zhou's validation list without them); raw_minus_kitti2015: the eigen_zhou lists without them.
  const bool stereo_drives = d.split == "kitti_raw_stereo" && d.train_list.empty();
  const bool minus_2015 = d.split == "raw_minus_kitti2015" || d.split == "kitti_raw_stereo";
  const std::string list_split = minus_2015 ? "eigen_zhou" : d.split;
  RawTrainingLists out;
  out.from_drives = stereo_drives;
  if (stereo_drives) {
    if (root.empty() || !fs::is_directory(root))
      throw ConfigError("data.root: data.split kitti_raw_stereo reads every drive under the KITTI raw folder, and '" +
                        root + "' is not a folder");
    out.train_list = root + " (every drive, cameras 02 and 03)";
  } else {
    out.train_list = d.train_list.empty() ? find_split_file(root, list_split, "train_files.txt") : d.train_list;
  }
  out.val_list = d.val_list.empty() ? find_split_file(root, list_split, "val_files.txt") : d.val_list;
  if (!stereo_drives && (out.train_list.empty() || !fs::exists(out.train_list)))
    throw ConfigError("data.train_list: no training list found (" +
                      (d.train_list.empty() ? "looked for " + root + "/splits/" + list_split +
                                                  "/train_files.txt and the shipped configs/splits/" + list_split
                                            : "'" + d.train_list + "' does not exist") +
                      ")");
  if (!out.val_list.empty() && !fs::exists(out.val_list)) out.val_list.clear();
  // GeoNet's flow data keeps the Eigen test drives: only the KITTI 2015 scenes are left out.
  const std::string scenes_file = stereo_drives ? "" : find_split_file(root, "eigen", "test_scenes.txt");
  if (!scenes_file.empty()) {
    out.test_scenes = read_scene_list(scenes_file);
    out.exclusions.push_back(scenes_file);
  }
  if (minus_2015) {
    const std::string stereo = find_split_file(root, "stereo", "test_scenes_stereo.txt");
    if (stereo.empty()) throw ConfigError("data.split " + d.split + ": no stereo/test_scenes_stereo.txt found");
    for (const auto& s : read_scene_list(stereo)) out.test_scenes.insert(s);
    out.exclusions.push_back(stereo);
  }
  const std::string static_file = shipped_config_dir() + "/splits/static_frames.txt";
  if (d.remove_static && fs::exists(static_file)) {
    out.static_frames = read_static_frames(static_file);
    out.exclusions.push_back(static_file);
  }
  return out;
}

std::string odometry_raw_drive(const std::string& sequence) {
  static const char* drives[] = {"2011_10_03_drive_0027", "2011_10_03_drive_0042", "2011_10_03_drive_0034",
                                 "2011_09_26_drive_0067", "2011_09_30_drive_0016", "2011_09_30_drive_0018",
                                 "2011_09_30_drive_0020", "2011_09_30_drive_0027", "2011_09_30_drive_0028",
                                 "2011_09_30_drive_0033", "2011_09_30_drive_0034"};
  if (sequence.size() != 2 || !std::isdigit(static_cast<unsigned char>(sequence[0])) ||
      !std::isdigit(static_cast<unsigned char>(sequence[1])))
    return "";
  const int n = std::stoi(sequence);
  return n <= 10 ? drives[n] : "";
}

TrainingDrives training_drives(const DataConfig& d) {
  TrainingDrives out;
  if (d.format == DataFormat::kSynthetic) return out;  // the world's own drives, none of KITTI's
  if (d.format == DataFormat::kVideo || !d.videos.empty()) {
    out.unknown = "trained on video clips (data.videos), which geo cannot match to KITTI drives";
    return out;
  }
  if (d.split == "odometry") {
    for (const auto& s : d.sequences)
      if (const auto drive = odometry_raw_drive(s); !drive.empty()) out.drives.insert(drive);
    return out;
  }
  // The root as training resolves it (a geo_synth world's raw/), when it is on this machine.
  std::string root = d.root;
  if (!root.empty() && !fs::exists(root + "/splits") && fs::is_directory(root + "/raw/splits")) root += "/raw";
  // Lists found at the root when training ran cannot be read from here: unknown, not "none".
  if (d.train_list.empty() && !fs::is_directory(root)) {
    out.unknown = "the training data root '" + d.root +
                  "' is not a folder here (a relative root resolves from where "
                  "geo_eval runs): the split lists training read cannot be checked";
    return out;
  }
  if (d.format == DataFormat::kPacked || (!root.empty() && is_packed_cache(root + "/train"))) {
    out.unknown = "trained from a packed cache (" + root + "), whose drives are not listed";
    return out;
  }
  try {
    const auto lists = raw_training_lists(d, root);
    if (lists.from_drives) out.drives = raw_drives_on_disk(root, lists.test_scenes);
    for (const auto& list : {lists.from_drives ? std::string() : lists.train_list, lists.val_list}) {
      if (list.empty()) continue;
      auto entries = read_split(list);
      exclude_entries(entries, lists.test_scenes, lists.static_frames);
      for (const auto& e : entries) out.drives.insert(e.scene());
    }
  } catch (const std::exception& e) {
    out.unknown = e.what();
  }
  return out;
}

}  // namespace geo
