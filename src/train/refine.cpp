#include "train/refine.h"

#include "core/config.h"
#include "pipeline/checkpoint.h"
#include "pipeline/run_folder.h"
#include "train/trainer.h"

#include <spdlog/spdlog.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <filesystem>
#include <stdexcept>

namespace geo {
namespace {

// Half video.yaml's 2e-4: on the unseen ends of the real KITTI runs 50 iterations at 1e-4 gave the
// best pair of ATEs of 1e-4 and 2e-4 (docs/video.md).
constexpr double kRefineLearningRate = 1e-4;

// `over`'s keys written into `base`, maps merged key by key.
void merge_into(YAML::Node base, const YAML::Node& over) {
  for (const auto& kv : over) {
    const auto key = kv.first.as<std::string>();
    if (kv.second.IsMap() && base[key] && base[key].IsMap()) merge_into(base[key], kv.second);
    else base[key] = kv.second;
  }
}

// video.yaml with the model's architecture and size, the clip, its camera and a one-stage schedule.
Config refine_config(const RefineOptions& o, const NetworkSpec& spec) {
  const std::string shipped = resolve_config_path("video.yaml");
  YAML::Node root = YAML::LoadFile(shipped);
  merge_into(root, YAML::Load(spec.to_yaml()));
  YAML::Node data = root["data"];
  data["videos"] = std::vector<std::string>{o.input};
  data["camera"] = YAML::Node(YAML::NodeType::Map);
  if (!spec.model.learn_intrinsics) data["camera"]["intrinsics"] = o.intrinsics;  // else the learned one trains on
  data["video"]["val_fraction"] = 0;  // every frame teaches: the clip is all there is
  data["video"]["crop"] = false;      // the whole frame, as geo_infer reads it
  YAML::Node stage = root["stages"][0];
  stage["name"] = "refine";
  stage["iterations"] = o.iterations;
  stage["learning_rate"] = kRefineLearningRate;
  stage["freeze_batch_norm"] = true;
  stage["weights"]["anchor"] = o.anchor;
  stage["hold_masked"] = 0;  // the anchor (--refine-anchor) is what holds depth here
  stage.remove("init");
  YAML::Node stages(YAML::NodeType::Sequence);
  stages.push_back(stage);
  root["stages"] = stages;
  YAML::Node log = root["logging"];
  log["interval"] = std::clamp<int64_t>(o.iterations / 10, 1, 100);
  log["checkpoint_interval"] = o.iterations;
  log["val_interval"] = 0;
  log["summary_interval"] = 0;
  log["keep_last"] = 1;
  root["run"]["name"] = "refine";
  root["run"]["device"] = o.device;
  root["run"]["threads"] = o.threads;
  YAML::Emitter e;
  e << root;
  return parse_config(e.c_str(), shipped + " (" + o.option + ")");
}

}  // namespace

std::string refine(const RefineOptions& o) {
  if (o.iterations < 1)
    throw std::runtime_error(o.option + " " + std::to_string(o.iterations) +
                             ": the number of training iterations on the input, at least 1");
  const std::string source_path = resolve_checkpoint(o.checkpoint);
  CheckpointFile source(source_path);
  const NetworkSpec spec = source.spec();
  if (!spec.model.learn_intrinsics && o.intrinsics.size() != 4)
    throw std::runtime_error(o.option + ": the camera of '" + o.input + "' is needed (fx fy cx cy)");
  TrainOptions train_options;
  train_options.run_dir = o.run_dir;
  train_options.init = source_path;
  spdlog::info("{} {}: training {} iteration(s) on {} from {} (run folder {})", o.option, o.iterations, o.iterations,
               o.input, source_path, o.run_dir);
  std::string run_dir;
  int code = 0;
  try {
    code = train(refine_config(o, spec), train_options, &run_dir);
  } catch (const std::exception& e) {  // a clip too short, without motion, ...: said as the refinement's
    throw std::runtime_error(o.option + " " + std::to_string(o.iterations) + ": " + e.what());
  }
  if (code != 0) return "";
  const std::string refined = RunFolder(run_dir).latest();
  // The refined DepthNet and PoseNet, the source's FlowNet (refinement trains no flow).
  Networks nets = source.networks();
  CheckpointFile(refined).load_networks(nets, true);
  const std::string out = run_dir + "/refined.pt";
  write_model_file(out, nets, false);
  return out;
}

}  // namespace geo
