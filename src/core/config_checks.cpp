// Validation of a parsed config: every key's rule, with the key's path and YAML line in the message
// (part of core/config; parsing and the entry points are config.cpp).
#include "core/camera_rule.h"
#include "core/config.h"
#include "core/config_text.h"

#include <initializer_list>
#include <set>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

namespace geo {
using namespace config_text;

// ---------------------------------------------------------------- validation

// A value already written as the configuration shows it.
struct Shown {
  std::string text;
};
inline std::string to_text(const Shown& v) { return v.text; }

class Checker {
 public:
  explicit Checker(const Config& config) : config_(config) {}

  // RAII prefix for nested structs: Checker::Scope s(c, "stages[0]");
  class Scope {
   public:
    Scope(Checker& c, const std::string& name) : c_(c), saved_(c.prefix_) {
      c_.prefix_ = join(saved_, name);
    }
    ~Scope() { c_.prefix_ = saved_; }

   private:
    Checker& c_;
    std::string saved_;
  };

  template <class T> void require(bool ok, const char* key, const T& value, const std::string& rule) {
    if (ok) return;
    const std::string path = join(prefix_, key);
    std::string where;
    auto it = config_.lines.find(path);
    if (it != config_.lines.end())
      where = it->second > 0 ? " (line " + std::to_string(it->second) + ")" : " (from --set)";
    else
      where = " (default)";
    errors_.push_back("key '" + path + "' = " + to_text(value) + where + ": " + rule);
  }

  void fail_if_any() const {
    if (errors_.empty()) return;
    std::string msg = config_.source + ": invalid configuration:";
    for (const auto& e : errors_) msg += "\n  " + e;
    throw ConfigError(msg);
  }

 private:
  const Config& config_;
  std::string prefix_;
  std::vector<std::string> errors_;
};

namespace {

// Every count of iterations is bounded where it is read, so that sums and products of counts (the
// total of the stages, iteration x batch) stay far from int64's limit: 1e12 iterations is more than
// any run can make.
constexpr int64_t kMaxCount = 1000000000000;
constexpr const char* kCountRange = "must be in 1..1000000000000";

// The keys of a section (camera, video) whose values differ from the section's defaults, with
// their values as the configuration shows them.
template <class Section> std::vector<std::pair<std::string, std::string>> non_defaults(const Section& section) {
  Section given = section, plain;
  std::vector<std::pair<std::string, std::string>> a, b, out;
  auto into = [](std::vector<std::pair<std::string, std::string>>& list) {
    return [&list](const char* name, const auto& value) {
      if constexpr (std::is_same_v<std::decay_t<decltype(value)>, bool>) list.emplace_back(name, value ? "true" : "false");
      else list.emplace_back(name, to_text(value));
    };
  };
  auto collect_a = into(a);
  auto collect_b = into(b);
  given.fields(collect_a);
  plain.fields(collect_b);
  for (size_t i = 0; i < a.size(); ++i)
    if (a[i].second != b[i].second) out.push_back(a[i]);
  return out;
}

bool one_of(const std::string& v, std::initializer_list<const char*> options) {
  for (const char* o : options)
    if (v == o) return true;
  return false;
}
}  // namespace

void ModelConfig::validate(Checker& c) const {
  c.require(encoder_depth == 18 || encoder_depth == 34 || encoder_depth == 50, "encoder_depth",
            encoder_depth, "must be 18, 34 or 50");
  c.require(fr_ratio >= 1 && fr_ratio <= 4096, "fr_ratio", fr_ratio, "must be in 1..4096");
  c.require(num_scales >= 1 && num_scales <= 4, "num_scales", num_scales, "must be in 1..4");
  c.require(bn_eps > 0, "bn_eps", bn_eps, "must be > 0");
  c.require(bn_momentum > 0 && bn_momentum <= 1, "bn_momentum", bn_momentum, "must be in (0, 1]");
}

void AugmentConfig::validate(Checker& c) const {
  c.require(scale_max >= 1.0 && scale_max <= 2.0, "scale_max", scale_max, "must be in [1, 2] (GeoNet: 1.15)");
  c.require(photometric_prob >= 0 && photometric_prob <= 1, "photometric_prob", photometric_prob,
            "must be in [0, 1]");
  c.require(gamma_min > 0 && gamma_min <= gamma_max, "gamma_min", gamma_min,
            "must be > 0 and <= gamma_max");
  c.require(brightness_min > 0 && brightness_min <= brightness_max, "brightness_min",
            brightness_min, "must be > 0 and <= brightness_max");
  c.require(color_min > 0 && color_min <= color_max, "color_min", color_min,
            "must be > 0 and <= color_max");
}

void DataConfig::validate(Checker& c) const {
  // Bounded where it is read: a network input of 4096x4096 already needs tens of GB to train.
  c.require(height >= 16 && height <= 4096 && height % 8 == 0, "height", height,
            "must be a multiple of 8 (4 pyramid scales) in 16..4096");
  c.require(width >= 16 && width <= 4096 && width % 8 == 0, "width", width,
            "must be a multiple of 8 (4 pyramid scales) in 16..4096");
  c.require(seq_length >= 3 && seq_length % 2 == 1, "seq_length", seq_length,
            "must be odd and >= 3 (target in the middle)");
  c.require(num_workers >= 0 && num_workers <= 64, "num_workers", num_workers, "must be in 0..64");
  c.require(one_of(val_split, {"list", "geonet"}), "val_split", val_split, "must be list or geonet");
  c.require(split != "odometry" || !sequences.empty(), "sequences", sequences,
            "must name at least one KITTI odometry sequence when data.split is odometry");
  c.require(!split.empty(), "split", split, "must not be empty (eigen_zhou, kitti_raw_stereo, raw_minus_kitti2015, odometry, ...)");
  {
    Checker::Scope s(c, "augment");
    augment.validate(c);
  }
  {
    Checker::Scope s(c, "synthetic");
    synthetic.validate(c);
  }
  c.require(format != DataFormat::kVideo || !videos.empty(), "videos", videos,
            "must name at least one video file or frame folder when data.format is video");
  // The clips' settings apply to data.videos only: given to other data they would go unused.
  const bool clips = uses_videos();
  c.require(clips || videos.empty(), "videos", videos,
            "data.format is " + to_text(format) + ", which trains on data.root, not on clips: set data.format=video " +
                "(or auto) to train on them, or leave data.videos empty");
  const std::string unused = "applies to data.videos only (data.format " + to_text(format) +
                             (format == DataFormat::kAuto ? " without clips" : "") + " reads " +
                             (format == DataFormat::kSynthetic ? "the in-memory world" : "data.root") +
                             ", whose camera comes with the data): remove it or train on clips";
  {
    Checker::Scope s(c, "camera");
    camera.validate(c);
    if (!clips)
      for (const auto& [key, value] : non_defaults(camera)) c.require(false, key.c_str(), Shown{value}, unused);
  }
  Checker::Scope s(c, "video");
  video.validate(c);
  if (!clips)
    for (const auto& [key, value] : non_defaults(video)) c.require(false, key.c_str(), Shown{value}, unused);
}

void CameraConfig::validate(Checker& c) const {
  const int given = !intrinsics.empty() + !calib_file.empty() + (fov_deg != 0);
  c.require(given <= 1, "intrinsics", intrinsics, "give one of camera.intrinsics, camera.calib_file or camera.fov_deg, not several");
  if (!intrinsics.empty()) {
    c.require(intrinsics.size() == 4, "intrinsics", intrinsics, "must be [fx, fy, cx, cy] in pixels of the original frames");
    if (intrinsics.size() == 4) {
      // The frames' size is known once a clip is opened (data/video/clip_camera.cpp checks again).
      const auto problem = camera_problem(intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]);
      c.require(problem.empty(), "intrinsics", intrinsics, problem);
    }
  }
  c.require(std::isfinite(fov_deg) && fov_deg >= 0 && fov_deg < 180, "fov_deg", fov_deg,
            "must be a horizontal field of view in (0, 180) degrees (0 = not given)");
}

void VideoDataConfig::validate(Checker& c) const {
  c.require(std::isfinite(fps) && fps >= 0 && fps <= 1000, "fps", fps, "must be in [0, 1000] (0 = every frame)");
  c.require(std::isfinite(source_fps) && source_fps >= 0 && source_fps <= 1000, "source_fps", source_fps,
            "must be in [0, 1000] (0 = unknown)");
  c.require(std::isfinite(static_threshold) && static_threshold >= 0 && static_threshold < 1, "static_threshold",
            static_threshold, "must be in [0, 1) (a fraction of changed pixels; 0 keeps every frame)");
  c.require(std::isfinite(standing_parallax) && standing_parallax >= 0 && standing_parallax <= 10, "standing_parallax",
            standing_parallax, "must be in [0, 10] pixels at a width of 416 (0 turns the standing-camera test off)");
  c.require(std::isfinite(standing_share) && standing_share > 0 && standing_share <= 1, "standing_share", standing_share,
            "must be in (0, 1] (the share of tracked features a rotation alone explains when the camera stands)");
  c.require(std::isfinite(val_fraction) && val_fraction >= 0 && val_fraction <= 0.5, "val_fraction", val_fraction,
            "must be in [0, 0.5]");
  c.require(val_block >= 3 && val_block <= 1000000, "val_block", val_block, "must be in 3..1000000 frames");
  c.require(std::isfinite(crop_y) && crop_y >= 0 && crop_y <= 1, "crop_y", crop_y, "must be in [0, 1]");
}

void SynthDataConfig::validate(Checker& c) const {
  c.require(one_of(preset, {"tiny", "kitti"}), "preset", preset, "must be tiny or kitti");
  c.require(seed >= 0, "seed", seed, "must be >= 0");
  c.require(drives >= 1 && drives <= 1000, "drives", drives, "must be in 1..1000");
  c.require(frames_per_drive >= 3 && frames_per_drive <= 100000, "frames_per_drive", frames_per_drive,
            "must be in 3..100000");
}

void LossConfig::validate(Checker& c) const {
  c.require(ssim_alpha >= 0 && ssim_alpha <= 1, "ssim_alpha", ssim_alpha, "must be in [0, 1]");
  c.require(occ_alpha1 >= 0, "occ_alpha1", occ_alpha1, "must be >= 0");
  c.require(occ_alpha2 >= 0, "occ_alpha2", occ_alpha2, "must be >= 0");
  c.require(consistency_a >= 0, "consistency_a", consistency_a, "must be >= 0");
  c.require(consistency_b >= 0, "consistency_b", consistency_b, "must be >= 0");
  const bool range_ok = image_range.size() == 2 &&
                        ((image_range[0] == -1.0 && image_range[1] == 1.0) ||
                         (image_range[0] == 0.0 && image_range[1] == 1.0));
  c.require(range_ok, "image_range", image_range, "must be [-1, 1] (GeoNet) or [0, 1]");
}

void LossWeights::validate(Checker& c) const {
  c.require(rigid >= 0, "rigid", rigid, "must be >= 0");
  c.require(flow >= 0, "flow", flow, "must be >= 0");
  c.require(disp_smooth >= 0, "disp_smooth", disp_smooth, "must be >= 0");
  c.require(flow_smooth >= 0, "flow_smooth", flow_smooth, "must be >= 0");
  c.require(flow_consistency >= 0, "flow_consistency", flow_consistency, "must be >= 0");
  c.require(ground >= 0, "ground", ground, "must be >= 0");
}

std::vector<std::string> NetworkSet::names() const {
  std::vector<std::string> out;
  for (const auto& n : enum_names(Net{}))
    if (has(n.value)) out.emplace_back(n.name);
  return out;
}

const std::vector<EnumName<Upsample>>& enum_names(Upsample) {
  static const std::vector<EnumName<Upsample>> n{{Upsample::kNearest, "nearest"}, {Upsample::kBilinear, "bilinear"}};
  return n;
}
const std::vector<EnumName<LrScheduleKind>>& enum_names(LrScheduleKind) {
  static const std::vector<EnumName<LrScheduleKind>> n{{LrScheduleKind::kConstant, "constant"},
                                                       {LrScheduleKind::kStep, "step"}};
  return n;
}
const std::vector<EnumName<DataFormat>>& enum_names(DataFormat) {
  static const std::vector<EnumName<DataFormat>> n{
      {DataFormat::kAuto, "auto"}, {DataFormat::kKittiRaw, "kitti_raw"}, {DataFormat::kPacked, "packed"},
      {DataFormat::kSynthetic, "synthetic"}, {DataFormat::kVideo, "video"}};
  return n;
}
const std::vector<EnumName<Precision>>& enum_names(Precision) {
  static const std::vector<EnumName<Precision>> n{
      {Precision::kFp32, "fp32"}, {Precision::kTf32, "tf32"}, {Precision::kBf16, "bf16"}};
  return n;
}
const std::vector<EnumName<BadSample>>& enum_names(BadSample) {
  static const std::vector<EnumName<BadSample>> n{{BadSample::kStop, "stop"}, {BadSample::kSkip, "skip"}};
  return n;
}
const std::vector<EnumName<Sampler>>& enum_names(Sampler) {
  static const std::vector<EnumName<Sampler>> n{{Sampler::kZeros, "zeros"}, {Sampler::kBorder, "border"}};
  return n;
}
const std::vector<EnumName<FlowMask>>& enum_names(FlowMask) {
  static const std::vector<EnumName<FlowMask>> n{{FlowMask::kOcclusion, "occlusion"},
                                                 {FlowMask::kConsistency, "consistency"}};
  return n;
}
const std::vector<EnumName<FlowReduction>>& enum_names(FlowReduction) {
  static const std::vector<EnumName<FlowReduction>> n{{FlowReduction::kPerSource, "per_source"},
                                                      {FlowReduction::kGeoNet, "geonet"}};
  return n;
}
const std::vector<EnumName<Net>>& enum_names(Net) {
  static const std::vector<EnumName<Net>> n{{Net::kDepth, "depth"}, {Net::kPose, "pose"}, {Net::kFlow, "flow"}};
  return n;
}

void StageConfig::validate(Checker& c) const {
  // Stage names become file names (checkpoints/<name>-<iteration>.pt, summaries/<name>-...).
  const bool plain = !name.empty() && name != "." && name != ".." &&
                     name.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_.-") ==
                         std::string::npos;
  c.require(plain, "name", name, "must be a plain name of letters, digits, '_', '-' and '.' (it names files)");
  // best-<name>.pt must not read as a checkpoint <stage>-NNNNNNNN.pt.
  const bool numbered = name.size() >= 9 && name[name.size() - 9] == '-' &&
                        name.find_first_not_of("0123456789", name.size() - 8) == std::string::npos;
  c.require(!numbered, "name", name, "must not end in '-' and eight digits (the checkpoints' numbering)");
  c.require(iterations > 0 && iterations <= kMaxCount, "iterations", iterations, kCountRange);
  c.require(!train.empty(), "train", train, "must name at least one of depth, pose, flow");
  c.require(learning_rate > 0 && learning_rate <= 1, "learning_rate", learning_rate, "must be in (0, 1] (GeoNet: 0.0002)");
  c.require(batch_size >= 1 && batch_size <= 65536, "batch_size", batch_size, "must be in 1..65536");
  c.require(lr_schedule != LrScheduleKind::kStep || lr_step > 0, "lr_step", lr_step,
            "must be > 0 when lr_schedule is step");
  c.require(lr_step >= 0 && lr_step <= kMaxCount, "lr_step", lr_step, "must be in 0..1000000000000");
  c.require(lr_gamma > 0 && lr_gamma <= 1, "lr_gamma", lr_gamma, "must be in (0, 1]");
  if (uses_flow())
    c.require(weights.flow > 0 || weights.flow_smooth > 0 || weights.flow_consistency > 0,
              "train", train, "trains flow, so at least one flow loss weight must be > 0");
  Checker::Scope s(c, "weights");
  weights.validate(c);
}

void OptimizerConfig::validate(Checker& c) const {
  c.require(type == "adam", "type", type, "must be adam (the paper's optimiser)");
  c.require(beta1 >= 0 && beta1 < 1, "beta1", beta1, "must be in [0, 1)");
  c.require(beta2 >= 0 && beta2 < 1, "beta2", beta2, "must be in [0, 1)");
  c.require(eps > 0, "eps", eps, "must be > 0");
  c.require(weight_decay >= 0, "weight_decay", weight_decay, "must be >= 0");
  c.require(grad_clip >= 0, "grad_clip", grad_clip, "must be >= 0 (0 = off)");
}

void LoggingConfig::validate(Checker& c) const {
  c.require(one_of(level, {"trace", "debug", "info", "warn", "error"}), "level", level,
            "must be trace, debug, info, warn or error");
  c.require(interval > 0 && interval <= kMaxCount, "interval", interval, kCountRange);
  c.require(summary_interval >= 0 && summary_interval <= kMaxCount, "summary_interval", summary_interval,
            "must be in 0..1000000000000 (0 = off)");
  c.require(checkpoint_interval > 0 && checkpoint_interval <= kMaxCount, "checkpoint_interval", checkpoint_interval,
            kCountRange);
  c.require(val_interval >= 0 && val_interval <= kMaxCount, "val_interval", val_interval,
            "must be in 0..1000000000000 (0 = off)");
  c.require(keep_last >= 1 && keep_last <= 1000000, "keep_last", keep_last, "must be in 1..1000000");
  c.require(max_bad_steps >= 1 && max_bad_steps <= 1000000, "max_bad_steps", max_bad_steps, "must be in 1..1000000");
}

bool is_device_name(const std::string& name) {
  const bool cuda_n = name.rfind("cuda:", 0) == 0 && name.size() > 5 &&
                      name.find_first_not_of("0123456789", 5) == std::string::npos;
  return one_of(name, {"auto", "cpu", "cuda"}) || cuda_n;
}

void RunConfig::validate(Checker& c) const {
  c.require(!name.empty(), "name", name, "must not be empty");
  c.require(!dir.empty(), "dir", dir, "must not be empty");
  c.require(seed >= 0, "seed", seed, "must be >= 0");
  c.require(is_device_name(device), "device", device, kDeviceNameRule);
  c.require(threads >= 0 && threads <= 1024, "threads", threads, "must be in 0..1024 (0 = all cores)");
  Checker::Scope s(c, "distributed");
  distributed.validate(c);
}

void DistributedConfig::validate(Checker& c) const {
  c.require(one_of(backend, {"auto", "nccl", "gloo"}), "backend", backend, "must be auto, nccl or gloo");
  c.require(timeout_s >= 1 && timeout_s <= 86400, "timeout_s", timeout_s, "must be in 1..86400 seconds");
  c.require(verify_interval >= 0 && verify_interval <= kMaxCount, "verify_interval", verify_interval,
            "must be in 0..1000000000000 (0 = never)");
}

void Config::validate() const {
  Checker c(*this);
  {
    Checker::Scope s(c, "model");
    model.validate(c);
  }
  {
    Checker::Scope s(c, "data");
    data.validate(c);
  }
  {
    Checker::Scope s(c, "loss");
    loss.validate(c);
  }
  c.require(!stages.empty(), "stages", stages.size(), "must list at least one stage");
  std::set<std::string> names;
  for (size_t i = 0; i < stages.size(); ++i) {
    Checker::Scope s(c, "stages[" + std::to_string(i) + "]");
    stages[i].validate(c);
    c.require(names.insert(stages[i].name).second, "name", stages[i].name,
              "stage names must be unique");
  }
  {
    Checker::Scope s(c, "optimizer");
    optimizer.validate(c);
  }
  {
    Checker::Scope s(c, "logging");
    logging.validate(c);
  }
  {
    Checker::Scope s(c, "run");
    run.validate(c);
  }
  c.fail_if_any();
}

}  // namespace geo
