#include "pipeline/checkpoint.h"

#include "core/files.h"
#include "core/mapped_archive.h"
#include "core/state_io.h"
#include "models/conv.h"
#include "models/int8.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>

namespace fs = std::filesystem;

namespace geo {
namespace {

constexpr const char* kModelFormat = "geo-model 1";
// A model file whose networks run in int8 only: their float kernels are left out (empty tensors),
// their int8 kernels kept instead ("int8_kernels_<network>": Int8Graph::kernels). Older geo
// versions refuse it by this name instead of mistaking it for float weights.
constexpr const char* kInt8ModelFormat = "geo-model 2 (int8 kernels)";
// The same with the int8 kernels beside the archive, read where they lie in the file
// (core/mapped_archive.h: "int8_kernels_<network>/<kernel>"), not copied: what geo_export --int8
// writes; "geo-model 2" files are still read.
constexpr const char* kInt8MappedFormat = "geo-model 3 (int8 kernels, mapped)";
constexpr const char* kNetworks[] = {"depth", "pose", "flow"};

// The int8 graph of a network of `nets` by its file name ("depth", "pose", "flow"); null when it
// has none or is absent.
const Int8Graph* int8_graph(const Networks& nets, const std::string& network) {
  if (network == "depth") return nets.depth->net->int8.get();
  if (network == "pose") return nets.pose->int8.get();
  return nets.flow ? nets.flow->net->int8.get() : nullptr;
}

void write_networks(torch::serialize::OutputArchive& archive, const Networks& nets,
                    std::optional<torch::ScalarType> floating) {
  auto put = [&](const char* key, const torch::nn::Module& m) {
    torch::serialize::OutputArchive sub;
    write_state(m, sub, floating);
    archive.write(key, sub);
  };
  put("depth", *nets.depth);
  put("pose", *nets.pose);
  if (nets.flow) put("flow", *nets.flow);
}

}  // namespace

void write_checkpoint(torch::serialize::OutputArchive& a, const CheckpointContents& c) {
  write_networks(a, c.networks, std::nullopt);
  if (c.optimizer) {
    torch::serialize::OutputArchive opt;
    c.optimizer->save(opt);
    a.write("optimizer", opt);
  }
  write_train_state(a, c.state);
  a.write("config", c10::IValue(to_yaml(c.config)));
  if (!c.init_configs.empty()) {
    c10::List<std::string> chain;
    for (const auto& y : c.init_configs) chain.push_back(y);
    a.write("init_configs", c10::IValue(chain));
  }
}

void write_train_state(torch::serialize::OutputArchive& a, const TrainState& s) {
  torch::serialize::OutputArchive state;
  state.write("stage", c10::IValue(s.stage));
  state.write("iteration", c10::IValue(s.iteration));
  state.write("best_score", c10::IValue(s.best_score));
  state.write("world_size", c10::IValue(s.world_size));
  state.write("validation_pending", c10::IValue(s.validation_pending));
  state.write("depth_held", c10::IValue(s.depth_held));
  a.write("train_state", state);
}

void write_model_file(const std::string& path, const Networks& nets, bool half) {
  // An int8 model's calibration: its ranges, so that loading it in int8 needs no frames; and when
  // its float kernels are gone (inference only), its int8 kernels.
  bool int8_only = false;
  for (const char* network : kNetworks)
    if (const auto* g = int8_graph(nets, network); g && g->quantized() && g->float_released()) int8_only = true;
  torch::serialize::OutputArchive a;
  a.write("geo_model_format", c10::IValue(std::string(int8_only ? kInt8MappedFormat : kModelFormat)));
  a.write("spec", c10::IValue(nets.spec.to_yaml()));
  write_networks(a, nets, half ? std::optional<torch::ScalarType>(torch::kHalf) : std::nullopt);
  std::map<std::string, torch::Tensor> kernels;
  for (const char* network : kNetworks) {
    const auto* g = int8_graph(nets, network);
    if (!g || !g->quantized()) continue;
    a.write(std::string("int8_") + network, g->ranges());
    if (!int8_only) continue;
    TORCH_CHECK(g->float_released(), "int8: a model whose networks let go of their float kernels in part");
    for (const auto& [name, t] : g->kernels()) kernels[std::string("int8_kernels_") + network + "/" + name] = t;
  }
  if (int8_only) save_archive_with_mapped(a, kernels, path);
  else save_archive(a, path);
}

void check_model_file_target(const std::string& label, const std::string& out, const std::string& source, bool force) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::exists(out)) return;
  if (fs::equivalent(out, source, ec))
    throw std::runtime_error(label + " '" + out + "' is the checkpoint being exported (" + source +
                             "): refusing to replace it");
  if (force) return;
  bool model_file = false;
  try {
    model_file = CheckpointFile(out).is_model_file();
  } catch (const std::exception&) {
  }
  if (!model_file)
    throw std::runtime_error(label + " '" + out +
                             "' exists and is not a geo_export model file (a training "
                             "checkpoint or another file): refusing to replace it; remove it or pass --force");
}

CheckpointFile::CheckpointFile(std::string path) : path_(std::move(path)) {
  if (has_mapped_tensors(path_)) {
    auto opened = open_mapped_archive(path_);
    archive_ = std::move(opened.archive);
    mapped_ = std::move(opened.tensors);
  } else {
    archive_ = open_archive(path_);
  }
  torch::serialize::InputArchive flow;
  has_flow_ = archive_.try_read("flow", flow);
  c10::IValue format;
  if (archive_.try_read("geo_model_format", format)) {
    const std::string name = format.isString() ? format.toStringRef() : "?";
    if (name != kModelFormat && name != kInt8ModelFormat && name != kInt8MappedFormat)
      throw std::runtime_error(path_ + ": model file format '" + name + "', this geo reads '" + kModelFormat + "', '" +
                               kInt8ModelFormat + "' and '" + kInt8MappedFormat + "'");
    int8_only_ = name != kModelFormat;
    if ((name == kInt8MappedFormat) != mapped_.has_value())
      throw std::runtime_error(path_ + ": model file format '" + name + "' " +
                               (mapped_ ? "in a container of mapped kernels" : "without its mapped kernels"));
    c10::IValue spec;
    if (!archive_.try_read("spec", spec) || !spec.isString())
      throw std::runtime_error(path_ + ": model file without its spec");
    model_file_ = true;
    spec_ = NetworkSpec::parse(spec.toStringRef(), path_ + " [spec]");
    return;
  }
  c10::IValue yaml;
  if (archive_.try_read("config", yaml) && yaml.isString()) {
    config_ = parse_config(yaml.toStringRef(), path_ + " [config]");
    spec_ = NetworkSpec::of(*config_);
  }
  c10::IValue chain;
  if (archive_.try_read("init_configs", chain)) {
    if (!chain.isList()) throw std::runtime_error(path_ + ": 'init_configs' is not a list of configs");
    for (const auto& y : chain.toListRef()) {
      if (!y.isString()) throw std::runtime_error(path_ + ": 'init_configs' holds a value that is not a config");
      init_configs_.push_back(y.toStringRef());
    }
  }
}

std::vector<std::string> CheckpointFile::lineage() const {
  std::vector<std::string> out;
  out.push_back(config_ ? to_yaml(*config_)
                        : "unknown: " + path_ +
                              (model_file_ ? " is a geo_export model file, which carries no training config"
                                           : " carries no training config"));
  out.insert(out.end(), init_configs_.begin(), init_configs_.end());
  return out;
}

NetworkSpec CheckpointFile::spec() const {
  if (!spec_)
    throw std::runtime_error(path_ + ": neither a geo_export model nor a geo_train checkpoint (no spec, no config)");
  return *spec_;
}

TrainState CheckpointFile::train_state() {
  if (model_file_)
    throw std::runtime_error(path_ + ": a geo_export model file, not a training checkpoint (it has no train state)");
  TrainState s;
  torch::serialize::InputArchive typed;
  if (archive_.try_read("train_state", typed)) {
    auto get = [&](const char* key) {
      c10::IValue v;
      if (!typed.try_read(key, v)) throw std::runtime_error(path_ + ": train_state without '" + key + "'");
      return v;
    };
    const auto stage = get("stage"), iteration = get("iteration"), best = get("best_score"), world = get("world_size");
    if (!stage.isInt() || !iteration.isInt() || !best.isDouble() || !world.isInt())
      throw std::runtime_error(path_ + ": train_state holds values of the wrong types");
    s.stage = stage.toInt();
    s.iteration = iteration.toInt();
    s.best_score = best.toDouble();
    s.world_size = world.toInt();
    // Absent in checkpoints written before they existed: nothing pending, depth not held.
    const auto flag = [&](const char* key, bool& out) {
      c10::IValue v;
      if (!typed.try_read(key, v)) return;
      if (!v.isBool()) throw std::runtime_error(path_ + ": train_state holds values of the wrong types");
      out = v.toBool();
    };
    flag("validation_pending", s.validation_pending);
    flag("depth_held", s.depth_held);
  } else {  // before the typed state: float64 [stage, iteration, best] and an int "world_size"
    torch::Tensor meta;
    if (!archive_.try_read("meta", meta) || meta.numel() != 3)
      throw std::runtime_error(path_ + ": not a geo training checkpoint (no train state)");
    meta = meta.to(torch::kFloat64);
    s.stage = static_cast<int64_t>(meta[0].item<double>());
    s.iteration = static_cast<int64_t>(meta[1].item<double>());
    s.best_score = meta[2].item<double>();
    c10::IValue world;
    if (archive_.try_read("world_size", world) && world.isInt()) s.world_size = world.toInt();
  }
  if (s.stage < 0 || s.iteration < 0 || s.world_size < 1 || std::isnan(s.best_score))
    throw std::runtime_error(path_ + ": implausible train state (stage " + std::to_string(s.stage) + ", iteration " +
                             std::to_string(s.iteration) + ", world size " + std::to_string(s.world_size) + ")");
  return s;
}

void CheckpointFile::load_networks(Networks& nets, bool allow_missing_flow, bool int8_kernels) {
  if (int8_only_ && !int8_kernels)
    throw std::runtime_error(path_ +
                             ": an int8 model file (geo_export --int8): its networks keep int8 kernels only and "
                             "run in int8 inference (precision int8); train, evaluate in float or export again "
                             "from the checkpoint it was written from");
  auto get = [&](const char* key, torch::nn::Module& m) {
    torch::serialize::InputArchive sub;
    if (!archive_.try_read(key, sub)) return false;
    read_state(m, sub, path_ + " [" + key + "]", int8_only_);
    return true;
  };
  if (!get("depth", *nets.depth)) throw std::runtime_error(path_ + ": no DepthNet in this checkpoint");
  if (!get("pose", *nets.pose)) throw std::runtime_error(path_ + ": no PoseNet in this checkpoint");
  if (nets.flow && !get("flow", *nets.flow) && !allow_missing_flow)
    throw std::runtime_error(path_ + ": no FlowNet in this checkpoint");
}

std::optional<torch::Tensor> CheckpointFile::int8_ranges(const std::string& network) {
  torch::Tensor ranges;
  if (!archive_.try_read("int8_" + network, ranges)) return std::nullopt;
  return ranges;
}

std::map<std::string, torch::Tensor> CheckpointFile::int8_kernels(const std::string& network) {
  if (int8_only_ && mapped_) return mapped_->under("int8_kernels_" + network + "/");
  std::map<std::string, torch::Tensor> kernels;
  torch::serialize::InputArchive sub;
  if (!int8_only_ || !archive_.try_read("int8_kernels_" + network, sub)) return kernels;
  for (const auto& key : sub.keys()) sub.read(key, kernels[key]);
  return kernels;
}

Networks CheckpointFile::networks() {
  Networks nets = [&] {
    const UninitialisedWeights every_weight_is_read_next;  // load_networks below is strict
    return Networks::create(spec(), has_flow_);
  }();
  load_networks(nets, false);
  return nets;
}

bool CheckpointFile::load_optimizer(torch::optim::Optimizer& optimizer) {
  torch::serialize::InputArchive opt;
  if (!archive_.try_read("optimizer", opt)) return false;
  optimizer.load(opt);
  // The state comes back on the device it was saved from: a CUDA run resumed on the CPU (or the
  // reverse) moves it to its parameters' device (all of them train on one).
  const auto& groups = optimizer.param_groups();
  const auto with_params =
      std::find_if(groups.begin(), groups.end(), [](const auto& g) { return !g.params().empty(); });
  if (with_params == groups.end()) return true;
  const torch::Device device = with_params->params().front().device();
  for (auto& entry : optimizer.state())
    if (auto* adam = dynamic_cast<torch::optim::AdamParamState*>(entry.second.get())) {
      if (adam->exp_avg().defined()) adam->exp_avg(adam->exp_avg().to(device));
      if (adam->exp_avg_sq().defined()) adam->exp_avg_sq(adam->exp_avg_sq().to(device));
      if (adam->max_exp_avg_sq().defined()) adam->max_exp_avg_sq(adam->max_exp_avg_sq().to(device));
    }
  return true;
}

}  // namespace geo
