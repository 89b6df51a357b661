#include "eval/protocol_parts.h"

#include "core/config.h"
#include "core/logging.h"
#include "data/kitti/splits.h"
#include "data/kitti/training_lists.h"
#include "data/text_io.h"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <set>

namespace fs = std::filesystem;

namespace geo {
namespace {

// A geo_synth world (its README.txt at `data_root` or above `root`): its kitti2015/ and odometry/
// scenes are rendered for them alone, none of them a raw drive.
bool is_synth_world(const std::string& data_root, const std::string& root) {
  for (const auto& dir : {data_root, root + "/.."}) {
    const std::string readme = dir + "/README.txt";
    if (fs::exists(readme) && read_text_file(readme).rfind("Synthetic KITTI-format world written by geo_synth", 0) == 0)
      return true;
  }
  return false;
}

// Which test drives the model trained on, its own run or any checkpoint of its init chain (each
// checkpoint records what its init was trained on): warned about and recorded in the result.
void check_training_drives(EvalResult& r, const Predictor& pred) {
  const auto& config = pred.training_config();
  if (!config) {
    r.training_drives_unknown = "the model carries no training config (a geo_export model file or an untrained model)";
    return;
  }
  struct Link {
    std::string what;  // "the model's training data (data.split X)" or "init 1 (data.split Y)"
    TrainingDrives drives;
  };
  std::vector<Link> links{
      {"the model's training data (data.split " + config->data.split + ")", training_drives(config->data)}};
  const auto& chain = pred.init_configs();
  for (size_t i = 0; i < chain.size(); ++i) {
    Link l;
    if (chain[i].rfind("unknown: ", 0) == 0) {
      l.what = "init " + std::to_string(i + 1);
      l.drives.unknown = "its weights started from a checkpoint whose training data is unknown: " + chain[i].substr(9);
    } else {
      const Config c = parse_config(chain[i], "init " + std::to_string(i + 1) + " of " + pred.path());
      l.what = "the data of the checkpoint it was initialised from" +
               std::string(i ? " (" + std::to_string(i + 1) + " links up)" : "") + " (data.split " + c.data.split + ")";
      l.drives = training_drives(c.data);
    }
    links.push_back(std::move(l));
  }
  std::set<std::string> leaked;
  for (const auto& l : links) {
    if (!l.drives.unknown.empty()) {  // a leak another link shows is still recorded
      if (r.training_drives_unknown.empty()) {
        r.training_drives_unknown = l.drives.unknown;
        spdlog::warn("cannot tell whether the model trained on test drives: {}", l.drives.unknown);
      }
      continue;
    }
    std::vector<std::string> here;
    for (const auto& d : r.test_drives)
      if (l.drives.drives.count(d)) here.push_back(d), leaked.insert(d);
    if (!here.empty())
      spdlog::warn(
          "{} holds {} of the {} drives of this test set: {}. These results are measured on training drives; "
          "train on data disjoint from the test set (README, KITTI)",
          l.what, here.size(), r.test_drives.size(), join_list(here, ", "));
  }
  for (const auto& d : r.test_drives)
    if (leaked.count(d)) r.test_drives_in_training.push_back(d);
}

}  // namespace

std::string split_root(const std::string& split, const std::string& root) {
  const std::string sub = split == "eigen" ? "/raw" : split == "kitti2015" ? "/kitti2015" : "/odometry";
  return fs::is_directory(root + sub) ? root + sub : root;
}

DepthScaling depth_scaling_named(const std::string& name) {
  if (name == "median") return DepthScaling::kMedian;
  if (name == "camera-height") return DepthScaling::kCameraHeight;
  if (name == "none") return DepthScaling::kNone;
  throw std::runtime_error("depth scaling '" + name + "': must be median, camera-height or none");
}

FlowResize flow_resize_named(const std::string& name) {
  if (name == "nearest") return FlowResize::kNearest;
  if (name == "bilinear") return FlowResize::kBilinear;
  throw std::runtime_error("flow resize '" + name + "': must be nearest or bilinear");
}

void check_eval_options(const EvalOptions& o) {
  if (o.split.empty()) throw std::runtime_error("--split is required (eigen, kitti2015 or odometry); see --help");
  if (o.split != "eigen" && o.split != "kitti2015" && o.split != "odometry")
    throw std::runtime_error("split '" + o.split + "': must be eigen, kitti2015 or odometry");
  if (o.scaling == DepthScaling::kCameraHeight && o.split == "kitti2015")
    throw std::runtime_error("--scaling camera-height is for --split eigen and odometry: flow has no scale to set");
  if (o.camera_height != 0 && o.scaling != DepthScaling::kCameraHeight)
    throw std::runtime_error(std::string("--camera-height is used by --scaling camera-height only (the scaling is '") +
                             (o.scaling == DepthScaling::kMedian ? "median" : "none") + "')");
}

EvalResult evaluate(const EvalOptions& o, PredictionSource& source) {
  Predictor* pred = source.model();
  if (!fs::is_directory(o.data_root))
    throw std::runtime_error("data root '" + o.data_root + "' is not a directory (--data-root)");
  const std::string root = split_root(o.split, o.data_root);
  EvalResult r;
  if (o.split == "eigen") r = eval_eigen(o, root, source);
  else if (o.split == "kitti2015") r = eval_kitti2015(o, root, source);
  else if (o.split == "odometry") r = eval_odometry(o, root, source);
  else throw std::runtime_error("unknown split '" + o.split + "' (eigen, kitti2015, odometry)");
  r.split = o.split;
  if (o.split == "eigen" || (o.split == "odometry" && pred && o.scaling == DepthScaling::kCameraHeight))
    r.scaling = o.scaling == DepthScaling::kMedian ? "median"
                : o.scaling == DepthScaling::kNone
                    ? "none"
                    : "camera-height " + std::to_string(camera_height_of(o, root)) + " m";
  r.source = source.name();
  if (pred) r.precision = pred->precision();
  r.data_root = root;
  if (o.split == "odometry") r.subset = "sequence " + o.sequence;
  if (!o.split_file.empty()) r.subset += (r.subset.empty() ? "list " : ", list ") + o.split_file;
  if (!is_synth_world(o.data_root, root)) {
    // Real KITTI: the 200 KITTI 2015 pairs come from the 29 raw drives of stereo/test_scenes_stereo.txt,
    // an odometry sequence 00-10 from one raw drive.
    if (o.split == "kitti2015") {
      const std::string scenes = find_split_file(root, "stereo", "test_scenes_stereo.txt");
      if (!scenes.empty())
        for (const auto& d : read_scene_list(scenes)) r.test_drives.push_back(d);
    } else if (o.split == "odometry") {
      if (const auto d = odometry_raw_drive(o.sequence); !d.empty()) r.test_drives.push_back(d);
    }
  }
  if (pred) check_training_drives(r, *pred);
  return r;
}

}  // namespace geo
