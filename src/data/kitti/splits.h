// Split lists (Eigen / Zhou et al. splits). Two formats are read alike:
//   "folder frame side"   e.g. "2011_09_26/2011_09_26_drive_0022_sync 473 r" (monodepth2, eigen_zhou)
//   "one image path"      e.g. "2011_09_26/2011_09_26_drive_0002_sync/image_02/data/0000000069.png"
// side l = camera 02 (image_02), r = camera 03. Odometry lists ("9 0 l") read as folder "9".
#pragma once

#include <cstdint>
#include <set>
#include <string>
#include <vector>

namespace geo {

struct SplitEntry {
  std::string folder;  // drive folder relative to the root, e.g. 2011_09_26/2011_09_26_drive_0022_sync
  int64_t frame = 0;   // frame index
  char side = 'l';     // 'l' (camera 02) or 'r' (camera 03)
  std::string line;    // the line as written (for messages)
  // The snippet's frames in order, the target in the middle, when they are not frame - L/2 ..
  // frame + L/2 (raw_drive_snippets: GeoNet's frame lists without the static frames); else empty.
  std::vector<int64_t> snippet;

  int64_t frame_at(int64_t offset) const {  // the frame `offset` places from the target
    return snippet.empty() ? frame + offset
                           : snippet.at(static_cast<size_t>(offset + static_cast<int64_t>(snippet.size()) / 2));
  }

  int camera() const { return side == 'r' ? 3 : 2; }
  std::string date() const;   // first path component of folder ("2011_09_26")
  std::string drive() const;  // last path component of folder ("2011_09_26_drive_0022_sync")
  std::string scene() const;  // drive() without "_sync" ("2011_09_26_drive_0022", as scene lists name it)
  // <root>/<folder>/image_0c/data/%010d.png for frame_at(offset).
  std::string image_path(const std::string& root, int64_t offset = 0) const;
};

// Parses one line in either format; throws std::runtime_error naming `where` on anything else.
SplitEntry parse_split_line(const std::string& line, const std::string& where);
// Reads a list file; the message names the file and line of a malformed entry.
std::vector<SplitEntry> read_split(const std::string& path);

// Drive names such as "2011_09_26_drive_0117" (eigen/test_scenes.txt).
std::set<std::string> read_scene_list(const std::string& path);
// "date drive frame" lines (static_frames.txt) as keys "drive_sync_folder frame" -> see static_key.
std::set<std::string> read_static_frames(const std::string& path);

// The first existing of <root>/splits/<split>/<file> and the shipped configs/splits/<split>/<file>;
// "" if none.
std::string find_split_file(const std::string& root, const std::string& split, const std::string& file);
std::string static_key(const std::string& drive_folder, int64_t frame);

// GeoNet's raw training snippets (kitti_raw_loader.py, its kitti_raw_stereo data): every frame of
// cameras 02 and 03 of every drive on disk (<root>/<date>/<drive>_sync/image_0c/data/*.png) whose
// scene is not in `test_scenes`, the `static_frames` removed from each drive's frame list, then a
// snippet around every entry with seq_length / 2 list neighbours on both sides in the same drive
// and camera (so a neighbour is the next frame that moves). Ordered by folder, camera, frame.
std::vector<SplitEntry> raw_drive_snippets(const std::string& root, const std::set<std::string>& test_scenes,
                                           const std::set<std::string>& static_frames, int64_t seq_length);
// The drives (scenes, "2011_09_26_drive_0005") raw_drive_snippets would read: every <date>/<drive>_sync
// folder under `root` not in `test_scenes`.
std::set<std::string> raw_drives_on_disk(const std::string& root, const std::set<std::string>& test_scenes);

// GeoNet's validation split (prepare_train_data.py: each frame to val.txt with probability 0.1):
// whether this snippet is held out, decided by a fixed hash of its drive, frame and camera, so that
// the choice is the same on every machine and for every order of reading.
bool in_geonet_validation(const SplitEntry& e);

// Removes entries whose drive is a test scene or whose frame is static; returns how many were removed.
size_t exclude_entries(std::vector<SplitEntry>& entries, const std::set<std::string>& test_scenes,
                       const std::set<std::string>& static_frames);

}  // namespace geo
