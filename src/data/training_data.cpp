#include "data/training_data.h"

#include "core/logging.h"
#include "core/progress.h"
#include "data/packed/packed.h"
#include "data/kitti/splits.h"
#include "data/kitti/training_lists.h"
#include "data/synth/synth_snippets.h"
#ifdef GEO_WITH_OPENCV
#include "data/kitti/sequence_dataset.h"
#include "data/video/video_clips.h"
#endif

#include <spdlog/spdlog.h>

#include <filesystem>

namespace fs = std::filesystem;

namespace geo {

namespace {

// A packed cache (geo_prepare): train/ and, when there, val/.
TrainingData open_packed(const DataConfig& d, TrainingData out) {
  out.format = "packed";
  // train/ and val/ each hold what the config asks for, and come from one geo_prepare run: a val/
  // left by an earlier run (another size, or a run killed before it rewrote val/) would choose
  // best-<stage>.pt on stale frames.
  const auto check = [&](const PackedSnippets& p, const std::string& part) {
    if (p.height() != d.height || p.width() != d.width || p.seq_length() != d.seq_length)
      throw ConfigError("packed cache '" + d.root + "/" + part + "' holds " + std::to_string(p.seq_length()) +
                        "-frame snippets at " + std::to_string(p.width()) + "x" + std::to_string(p.height()) +
                        " but data.width/height/seq_length ask for " + std::to_string(d.seq_length) + " frames at " +
                        std::to_string(d.width) + "x" + std::to_string(d.height) + " (re-run geo_prepare)");
  };
  auto train = std::make_shared<PackedSnippets>(d.root + "/train");
  check(*train, "train");
  out.train = train;
  if (has_packed_cache_files(d.root + "/val")) {
    auto val = std::make_shared<PackedSnippets>(d.root + "/val");
    check(*val, "val");
    if (val->pack() != train->pack())
      throw ConfigError("packed cache '" + d.root +
                        "': val/ was written by another geo_prepare run than train/ (pack '" + val->pack() +
                        "', train/ '" + train->pack() + "'): a stale validation set; re-run geo_prepare --out " +
                        d.root + ", or remove " + d.root + "/val to train without validation");
    out.val = val;
  }
  out.train_list = d.root + "/train";
  return out;
}

#ifdef GEO_WITH_OPENCV
// KITTI odometry (data.split odometry): the snippets of data.sequences.
TrainingData open_odometry(const DataConfig& d, TrainingData out) {
  OdometryDatasetOptions oo;
  oo.root = d.root;
  oo.sequences = d.sequences;
  oo.height = d.height;
  oo.width = d.width;
  oo.seq_length = d.seq_length;
  out.format = "kitti_odometry";
  out.train = std::make_shared<OdometryDataset>(oo);
  out.train_list = d.root + "/sequences/{" + join_list(d.sequences, ",") + "}";
  if (out.train->size() == 0)
    throw ConfigError("data.sequences: no " + std::to_string(d.seq_length) + "-frame snippet in " + out.train_list);
  return out;
}

// A list's first entry missing on disk: the target, or the first absent neighbour.
std::string first_missing_frame(const DataConfig& d, const std::string& list) {
  const auto first = read_split(list).front();
  for (int64_t o = -d.seq_length / 2; o <= d.seq_length / 2; ++o)
    if (first.frame + o < 0 || !fs::exists(first.image_path(d.root, o)))
      return first.frame + o < 0 ? "frame " + std::to_string(first.frame + o) + " of " + first.folder
                                 : first.image_path(d.root, o);
  return first.image_path(d.root);
}

// KITTI raw's training snippets of a split (a list, or every drive: kitti_raw_stereo) without the
// test scenes and static frames; with data.val_split geonet, GeoNet's 10% moved into `held_out`.
std::vector<SplitEntry> raw_training_entries(const DataConfig& d, const RawTrainingLists& lists, TrainingData& out,
                                             std::vector<SplitEntry>& held_out) {
  auto entries = lists.from_drives ? raw_drive_snippets(d.root, lists.test_scenes, lists.static_frames, d.seq_length)
                                   : read_split(out.train_list);
  const size_t listed = entries.size();
  if (lists.from_drives && entries.empty())
    throw ConfigError("data.split kitti_raw_stereo: no " + std::to_string(d.seq_length) + "-frame snippet under '" +
                      d.root +
                      "' (looked for <date>/<drive>_sync/image_02|03/data/*.png outside the KITTI 2015 scenes of " +
                      join_list(out.exclusions, ",") + ")");
  if (!lists.from_drives) out.excluded = exclude_entries(entries, lists.test_scenes, lists.static_frames);
  if (entries.empty())
    throw ConfigError("data.split " + d.split + ": all " + std::to_string(listed) + " entries of " + out.train_list +
                      " are excluded (test scenes or static frames listed in " + join_list(out.exclusions, ",") + ")");
  if (lists.from_drives && d.val_split == "list")
    spdlog::warn(
        "data.split kitti_raw_stereo with data.val_split list: the validation list's frames are in the "
        "drives trained on (most are training frames), so validation measures fit, not generalisation; "
        "data.val_split geonet holds GeoNet's 10% out of training (configs/rigid_geonet.yaml does)");
  if (d.val_split == "geonet") {
    std::vector<SplitEntry> kept;
    for (auto& e : entries) (in_geonet_validation(e) ? held_out : kept).push_back(std::move(e));
    entries = std::move(kept);
    out.val_list = "GeoNet's 10% of " + out.train_list;
  }
  return entries;
}

// KITTI raw (the Eigen split's lists, raw_minus_kitti2015, kitti_raw_stereo's drives).
TrainingData open_kitti_raw(const DataConfig& d, TrainingData out) {
  out.format = "kitti_raw";
  const bool minus_2015 = d.split == "raw_minus_kitti2015" || d.split == "kitti_raw_stereo";
  const auto lists = raw_training_lists(d, d.root);
  out.train_list = lists.train_list;
  out.val_list = lists.val_list;
  out.exclusions = lists.exclusions;
  SequenceDatasetOptions so;
  so.root = d.root;
  so.height = d.height;
  so.width = d.width;
  so.seq_length = d.seq_length;
  std::vector<SplitEntry> held_out;  // data.val_split geonet: GeoNet's 10% of the training snippets
  auto train = std::make_shared<SequenceDataset>(raw_training_entries(d, lists, out, held_out), so);
  out.dropped = train->dropped();
  if (train->size() == 0 && !lists.from_drives)
    throw ConfigError("data.root '" + d.root + "': none of the " + std::to_string(out.dropped) + " entries of " +
                      out.train_list + " has all its " + std::to_string(d.seq_length) +
                      " frames on disk (first missing: " + first_missing_frame(d, out.train_list) + ")");
  out.train = train;
  if (d.val_split == "geonet") {
    auto val = std::make_shared<SequenceDataset>(std::move(held_out), so);
    if (val->size() > 0) out.val = val;
  } else if (!out.val_list.empty()) {
    auto val_entries = read_split(out.val_list);
    if (minus_2015) out.excluded += exclude_entries(val_entries, lists.test_scenes, {});
    auto val = std::make_shared<SequenceDataset>(std::move(val_entries), so);
    if (val->size() > 0) out.val = val;
  }
  return out;
}
#endif

// data.root's training data: a packed cache, KITTI odometry or KITTI raw.
TrainingData open_at(const DataConfig& d, TrainingData out) {
  // A folder with any cache file is a cache: a corrupt or partial one is an error naming it, never a
  // silent fall-back to the raw KITTI lists.
  if (d.format == DataFormat::kPacked || (d.format == DataFormat::kAuto && has_packed_cache_files(d.root + "/train")))
    return open_packed(d, std::move(out));
#ifndef GEO_WITH_OPENCV
  throw ConfigError("data.root '" + d.root + "' is not a packed cache (no " + d.root +
                    "/train/index.txt), and this "
                    "geo was built without OpenCV (-DGEO_WITH_OPENCV=OFF), so it cannot read KITTI's image files: "
                    "train from a packed cache (geo_prepare, on a machine with OpenCV) or from the built-in "
                    "synthetic world (data.format: synthetic)");
#else
  return d.split == "odometry" ? open_odometry(d, std::move(out)) : open_kitti_raw(d, std::move(out));
#endif
}

TrainingData open_synthetic(const DataConfig& d) {
  const auto& sc = d.synthetic;
  SynthOptions world = synth_world_at(sc.preset, d.height, d.width);
  world.seed = static_cast<uint64_t>(sc.seed);
  world.train_drives = sc.drives;
  world.frames_per_drive = sc.frames_per_drive;
  if (world.frames_per_drive < d.seq_length)
    throw ConfigError("data.synthetic.frames_per_drive " + std::to_string(sc.frames_per_drive) +
                      " is shorter than one snippet (data.seq_length " + std::to_string(d.seq_length) + ")");
  spdlog::info("rendering the synthetic world in memory: preset {}, seed {}, {} drives of {} frames at {}x{}",
               sc.preset, sc.seed, sc.drives, sc.frames_per_drive, d.width, d.height);
  auto sets = render_synth_snippets(world, d.seq_length);
  TrainingData out;
  out.root = "memory";
  out.format = "synthetic";
  out.train = sets.train;
  out.val = sets.val;
  out.train_list = "synthetic world, seed " + std::to_string(sc.seed);
  if (out.train->size() == 0)
    throw ConfigError("data.synthetic: " + std::to_string(sc.drives) + " drives of " +
                      std::to_string(sc.frames_per_drive) + " frames hold no training snippet");
  return out;
}

TrainingData open_videos(const DataConfig& d) {
#ifndef GEO_WITH_OPENCV
  (void)d;
  throw ConfigError(
      "data.videos: this geo was built without OpenCV (-DGEO_WITH_OPENCV=OFF), so it cannot decode "
      "videos or image files: pack the clips into a cache with geo_prepare on a machine with OpenCV");
#else
  auto clips = open_video_clips(d);
  for (const auto& line : clips.report) spdlog::info("{}", line);
  for (const auto& line : clips.warnings) spdlog::warn("{}", line);
  TrainingData out;
  out.root = join_list(d.videos, ",");
  out.format = "video";
  out.train = clips.train;
  out.val = clips.val;
  out.train_list = "data.videos [" + out.root + "]";
  out.clip_records = clips.records;
  return out;
#endif
}

}  // namespace

TrainingData open_training_data(const DataConfig& d) {
  if (d.format == DataFormat::kSynthetic) return open_synthetic(d);
  if (d.uses_videos()) {
    if (!d.root.empty())
      throw ConfigError("data.root '" + d.root + "' and data.videos are both set: train from one of them");
    return open_videos(d);
  }
  if (d.root.empty())
    throw ConfigError(
        "data.root is empty: set it in the config or with --set data.root=DIR "
        "(a KITTI raw folder, a geo_prepare cache or a geo_synth world's raw/ folder), or "
        "use the built-in synthetic world: --set data.format=synthetic");
  if (!fs::is_directory(d.root)) throw ConfigError("data.root '" + d.root + "' is not a directory");
  TrainingData out;
  out.root = d.root;
  // A geo_synth --out folder holds raw/, kitti2015/ and odometry/: training reads raw/ (odometry/
  // for the odometry split).
  if (d.split == "odometry") {
    if (!fs::is_directory(d.root + "/sequences") && fs::is_directory(d.root + "/odometry/sequences"))
      out.root = d.root + "/odometry";
  } else if (!has_packed_cache_files(d.root + "/train") && !fs::exists(d.root + "/splits") &&
             fs::is_directory(d.root + "/raw") && fs::is_directory(d.root + "/raw/splits")) {
    out.root = d.root + "/raw";
  }
  DataConfig dr = d;
  dr.root = out.root;
  return open_at(dr, std::move(out));
}

bool write_packed_cache(const TrainingData& data, const DataConfig& config, const std::string& out) {
  // One identifier for train/ and val/: the trainer refuses a val/ left by another run.
  const std::string pack_id = new_pack_id();
  auto pack = [&](const SnippetSource& src, const std::string& dir) {
    PackedWriter w(dir, config.height, config.width, config.seq_length, pack_id);
    Progress progress(dir, static_cast<int64_t>(src.size()), 500, "snippets");
    for (size_t i = 0; i < src.size(); ++i) {
      w.add(src.get(i));
      progress.update(static_cast<int64_t>(i + 1));
    }
    w.finish();
  };
  pack(*data.train, out + "/train");
  if (data.val) {
    pack(*data.val, out + "/val");
  } else if (has_packed_cache_files(out + "/val")) {  // an earlier run's: no longer this cache's
    remove_packed_cache_files(out + "/val");
    return true;
  }
  return false;
}

}  // namespace geo
