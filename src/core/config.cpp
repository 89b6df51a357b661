#include "core/config.h"
#include "core/files.h"
#include "core/paths.h"  // generated: GEO_SOURCE_DIR

#include <spdlog/spdlog.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

namespace geo {
namespace fs = std::filesystem;

namespace {

std::string join(const std::string& prefix, const std::string& key) {
  return prefix.empty() ? key : prefix + "." + key;
}

// Formats a double with the fewest digits that read back to the same value; plain decimals (700,
// 0.0002) where up to 6 decimals do, never 7e+02.
std::string format_double(double v) {
  if (std::isfinite(v) && std::fabs(v) < 1e15 && (v == 0 || std::fabs(v) >= 1e-4)) {
    for (int decimals = 0; decimals <= 6; ++decimals) {
      std::ostringstream os;
      os.setf(std::ios::fixed);
      os.precision(decimals);
      os << v;
      if (std::stod(os.str()) == v) return os.str();
    }
  }
  for (int precision = 1; precision <= 17; ++precision) {
    std::ostringstream os;
    os.precision(precision);
    os << v;
    if (std::stod(os.str()) == v) return os.str();
  }
  std::ostringstream os;
  os.precision(17);
  os << v;
  return os.str();
}

template <class T> std::string to_text(const T& v) {
  if constexpr (std::is_enum_v<T>) {
    return std::string("'") + name_of(v) + "'";
  } else {
    std::ostringstream os;
    os << v;
    return os.str();
  }
}
std::string to_text(double v) { return format_double(v); }
std::string to_text(const std::string& v) { return "'" + v + "'"; }
std::string to_text(const std::vector<std::string>& v) {
  std::string s = "[";
  for (size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + v[i];
  return s + "]";
}
std::string to_text(const std::vector<double>& v) {
  std::string s = "[";
  for (size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + format_double(v[i]);
  return s + "]";
}
std::string to_text(const NetworkSet& v) { return to_text(v.names()); }

template <class E> std::string valid_names() {
  std::string all;
  for (const auto& n : enum_names(E{})) all += (all.empty() ? "" : ", ") + std::string(n.name);
  return all;
}

// ---------------------------------------------------------------- parsing

struct ParseContext {
  std::string source;
  std::map<std::string, int>* lines;
  std::set<std::string> overridden;  // key paths set by --set

  std::string where(const std::string& path, const YAML::Node& node) const {
    if (overridden.count(path)) return source + " (--set " + path + ")";
    return source + " line " + std::to_string(node.Mark().line + 1);
  }
  void record(const std::string& path, const YAML::Node& node) {
    (*lines)[path] = overridden.count(path) ? 0 : node.Mark().line + 1;
  }
};

template <class T> void read_value(const YAML::Node& node, const std::string& path, T& out,
                                   ParseContext& ctx);

template <class T> const char* type_name();
template <> const char* type_name<int>() { return "an integer"; }
template <> const char* type_name<int64_t>() { return "an integer"; }
template <> const char* type_name<double>() { return "a number"; }
template <> const char* type_name<bool>() { return "a boolean (true/false)"; }
template <> const char* type_name<std::string>() { return "a string"; }

template <class T> void read_scalar(const YAML::Node& node, const std::string& path, T& out,
                                    ParseContext& ctx) {
  std::string shown = node.IsScalar() ? "'" + node.Scalar() + "'" : "a list or map";
  if (!node.IsScalar())
    throw ConfigError(ctx.where(path, node) + ": key '" + path + "' must be " + type_name<T>() +
                      ", got " + shown);
  if constexpr (std::is_integral_v<T> && !std::is_same_v<T, bool>) {
    // Plain decimal only: yaml-cpp reads 010 as octal 8 and 0x10 as 16, which nobody means in a
    // count of iterations.
    const std::string& t = node.Scalar();
    const size_t digits = !t.empty() && (t[0] == '+' || t[0] == '-') ? 1 : 0;  // where the digits start
    const bool decimal = !t.empty() && t.size() > digits && t.find_first_not_of("0123456789", digits) == std::string::npos &&
                         (t.size() == digits + 1 || t[digits] != '0');
    if (!decimal)
      throw ConfigError(ctx.where(path, node) + ": key '" + path + "' must be " + type_name<T>() +
                        " written in decimal without leading zeros, got " + shown);
  }
  try {
    out = node.as<T>();
  } catch (const YAML::Exception&) {
    throw ConfigError(ctx.where(path, node) + ": key '" + path + "' must be " + type_name<T>() +
                      ", got " + shown);
  }
  if constexpr (std::is_floating_point_v<T>) {
    if (!std::isfinite(out))
      throw ConfigError(ctx.where(path, node) + ": key '" + path + "' must be finite, got " +
                        shown);
  }
}

struct ParseVisitor {
  const YAML::Node& node;
  std::string prefix;
  ParseContext& ctx;
  std::vector<std::string> known;

  template <class T> void operator()(const char* key, T& out) {
    known.emplace_back(key);
    const YAML::Node child = node[key];
    if (!child.IsDefined()) return;  // keep the default
    const std::string path = join(prefix, key);
    if (child.IsNull()) {
      // An empty section keeps its defaults; an empty value ("iterations:", "iterations: ~") is a
      // value left out by mistake, never silently the default.
      if constexpr (std::is_arithmetic_v<T> || std::is_same_v<T, std::string> || std::is_enum_v<T>)
        throw ConfigError(ctx.where(path, child) + ": key '" + path + "' has no value (give one, or leave the key out " +
                          "for the default)");
      return;
    }
    ctx.record(path, child);
    read_value(child, path, out, ctx);
  }

  void reject_unknown() const {
    std::map<std::string, int> seen;  // key -> line
    for (const auto& kv : node) {
      if (!kv.first.IsScalar())  // e.g. '{a: 1}: 2' or '[x]: 2'
        throw ConfigError(ctx.where(prefix.empty() ? "<top level>" : prefix, kv.first) +
                          ": a key must be a plain name, got a list or map");
      const std::string key = kv.first.Scalar();
      const int line = kv.first.Mark().line + 1;
      if (!seen.emplace(key, line).second)
        throw ConfigError(ctx.where(join(prefix, key), kv.first) + ": key '" + join(prefix, key) +
                          "' is given twice (lines " + std::to_string(seen[key]) + " and " + std::to_string(line) + ")");
      if (std::find(known.begin(), known.end(), key) != known.end()) continue;
      std::string valid;
      for (const auto& k : known) valid += (valid.empty() ? "" : ", ") + k;
      throw ConfigError(ctx.where(join(prefix, key), kv.first) + ": unknown key '" +
                        join(prefix, key) + "' (valid keys here: " + valid + ")");
    }
  }
};

void read_value(const YAML::Node& n, const std::string& p, int& o, ParseContext& c) {
  read_scalar(n, p, o, c);
}
void read_value(const YAML::Node& n, const std::string& p, int64_t& o, ParseContext& c) {
  read_scalar(n, p, o, c);
}
void read_value(const YAML::Node& n, const std::string& p, double& o, ParseContext& c) {
  read_scalar(n, p, o, c);
}
void read_value(const YAML::Node& n, const std::string& p, bool& o, ParseContext& c) {
  read_scalar(n, p, o, c);
}
void read_value(const YAML::Node& n, const std::string& p, std::string& o, ParseContext& c) {
  read_scalar(n, p, o, c);
}

template <class T> void read_value(const YAML::Node& node, const std::string& path,
                                   std::vector<T>& out, ParseContext& ctx) {
  if (!node.IsSequence())
    throw ConfigError(ctx.where(path, node) + ": key '" + path + "' must be a list");
  out.clear();
  for (size_t i = 0; i < node.size(); ++i) {
    T item{};
    const std::string item_path = path + "[" + std::to_string(i) + "]";
    ctx.record(item_path, node[i]);
    read_value(node[i], item_path, item, ctx);
    out.push_back(std::move(item));
  }
}

template <class E> void read_enum(const YAML::Node& node, const std::string& path, E& out, ParseContext& ctx) {
  std::string name;
  read_scalar(node, path, name, ctx);
  for (const auto& n : enum_names(E{}))
    if (name == n.name) {
      out = n.value;
      return;
    }
  throw ConfigError(ctx.where(path, node) + ": key '" + path + "' must be one of " + valid_names<E>() +
                    ", got '" + name + "'");
}

void read_value(const YAML::Node& node, const std::string& path, NetworkSet& out, ParseContext& ctx) {
  if (!node.IsSequence())
    throw ConfigError(ctx.where(path, node) + ": key '" + path + "' must be a list of " + valid_names<Net>() +
                      " (e.g. [depth, pose])");
  out = NetworkSet{false, false, false};
  for (size_t i = 0; i < node.size(); ++i) {
    Net net{};
    const std::string item_path = path + "[" + std::to_string(i) + "]";
    ctx.record(item_path, node[i]);
    read_enum(node[i], item_path, net, ctx);
    (net == Net::kDepth ? out.depth : net == Net::kPose ? out.pose : out.flow) = true;
  }
}

// Structs: anything with fields(); enumerations by name.
template <class T> void read_value(const YAML::Node& node, const std::string& path, T& out,
                                   ParseContext& ctx) {
  if constexpr (std::is_enum_v<T>) {
    read_enum(node, path, out, ctx);
  } else {
    if (!node.IsMap())
      throw ConfigError(ctx.where(path, node) + ": key '" + (path.empty() ? "<top>" : path) +
                        "' must be a map of keys");
    ParseVisitor visitor{node, path, ctx, {}};
    out.fields(visitor);
    visitor.reject_unknown();
  }
}

// ---------------------------------------------------------------- emitting

struct EmitVisitor {
  YAML::Emitter& out;
  template <class T> void operator()(const char* key, T& value) {
    out << YAML::Key << key << YAML::Value;
    emit(value);
  }
  void emit(int v) { out << v; }
  void emit(int64_t v) { out << v; }
  void emit(bool v) { out << v; }
  void emit(double v) { out << format_double(v); }
  void emit(std::string& v) {
    if (v.empty()) out << YAML::DoubleQuoted << v;
    else out << v;
  }
  template <class T> void emit(std::vector<T>& v) {
    out << YAML::BeginSeq;
    for (auto& item : v) emit(item);
    out << YAML::EndSeq;
  }
  void emit(std::vector<std::string>& v) {
    out << YAML::Flow << YAML::BeginSeq;
    for (auto& item : v) out << item;
    out << YAML::EndSeq;
  }
  void emit(NetworkSet& v) {
    auto names = v.names();
    emit(names);
  }
  void emit(std::vector<double>& v) {
    out << YAML::Flow << YAML::BeginSeq;
    for (double item : v) out << format_double(item);
    out << YAML::EndSeq;
  }
  template <class T> void emit(T& s) {
    if constexpr (std::is_enum_v<T>) {
      out << name_of(s);
    } else {
      out << YAML::BeginMap;
      s.fields(*this);
      out << YAML::EndMap;
    }
  }
};

// ---------------------------------------------------------------- overrides

// Splits "stages[0].learning_rate" or "stages.0.learning_rate" into parts. Brackets must hold an
// index of at most 6 digits; names are letters, digits and '_'. Throws ConfigError naming the key.
std::vector<std::string> split_key(const std::string& key) {
  auto bad = [&](const std::string& why) {
    return ConfigError("--set key '" + key + "': " + why + " (expected e.g. stages[0].learning_rate)");
  };
  std::vector<std::string> parts;
  size_t i = 0;
  while (i < key.size()) {
    if (key[i] == '[') {
      const auto close = key.find(']', i);
      if (close == std::string::npos) throw bad("unclosed '['");
      const std::string index = key.substr(i + 1, close - i - 1);
      if (index.empty() || index.size() > 6 || !std::all_of(index.begin(), index.end(), ::isdigit))
        throw bad("'[" + index + "]' is not a list index (0, 1, ...)");
      parts.push_back(index);
      i = close + 1;
      if (i < key.size() && key[i] != '.' && key[i] != '[') throw bad("unexpected text after ']'");
      if (i < key.size() && key[i] == '.') ++i;
      continue;
    }
    const auto end = key.find_first_of(".[]", i);
    const std::string name = key.substr(i, end == std::string::npos ? std::string::npos : end - i);
    if (name.empty() || !std::all_of(name.begin(), name.end(), [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; }))
      throw bad("'" + name + "' is not a key name");
    if (std::all_of(name.begin(), name.end(), ::isdigit) && name.size() > 6) throw bad("index " + name + " is too large");
    parts.push_back(name);
    if (end == std::string::npos) break;
    if (key[end] == ']') throw bad("unexpected ']'");
    i = key[end] == '.' ? end + 1 : end;
    if (key[end] == '.' && i == key.size()) throw bad("ends with '.'");
  }
  return parts;
}

std::string canonical_key(const std::vector<std::string>& parts) {
  std::string path;
  for (const auto& p : parts) {
    bool index = !p.empty() && std::all_of(p.begin(), p.end(), ::isdigit);
    path += index ? "[" + p + "]" : (path.empty() ? p : "." + p);
  }
  return path;
}

void apply_override(YAML::Node& root, const std::string& text, ParseContext& ctx) {
  const auto eq = text.find('=');
  if (eq == std::string::npos || eq == 0)
    throw ConfigError("--set '" + text + "': expected key.path=value");
  const auto parts = split_key(text.substr(0, eq));
  if (parts.empty()) throw ConfigError("--set '" + text + "': empty key");
  if (text.find_first_not_of(" \t", eq + 1) == std::string::npos)
    throw ConfigError("--set '" + text + "': empty value (for an empty string write " + text.substr(0, eq) + "='')");
  YAML::Node value;
  try {
    value = YAML::Load(text.substr(eq + 1));
  } catch (const YAML::Exception& e) {
    throw ConfigError("--set '" + text + "': value is not valid YAML: " + e.what());
  }
  YAML::Node node = root;
  for (size_t i = 0; i + 1 < parts.size(); ++i) {
    const auto& part = parts[i];
    const bool index = std::all_of(part.begin(), part.end(), ::isdigit);
    if (index) {
      const size_t k = std::stoul(part);
      if (!node.IsSequence() || k >= node.size())
        throw ConfigError("--set '" + text + "': '" + canonical_key({parts.begin(), parts.begin() + i + 1}) +
                          "' does not exist (the list has " +
                          std::to_string(node.IsSequence() ? node.size() : 0) + " entries)");
      node.reset(node[k]);
    } else {
      if (!node[part]) {
        // Sequences (stages) must exist to be indexed; maps are created on demand.
        node[part] = YAML::Node(YAML::NodeType::Map);
      }
      node.reset(node[part]);
    }
  }
  const auto& last = parts.back();
  if (std::all_of(last.begin(), last.end(), ::isdigit)) {
    const size_t k = std::stoul(last);
    if (!node.IsSequence() || k >= node.size())
      throw ConfigError("--set '" + text + "': index " + last + " is out of range");
    node[k] = value;
  } else {
    node[last] = value;
  }
  ctx.overridden.insert(canonical_key(parts));
}

// For `stages[i].x` overrides when the file has no stages: materialise the defaults first.
void materialise_default_stages(YAML::Node& root) {
  if (root["stages"]) return;
  YAML::Emitter out;
  Config defaults;
  EmitVisitor visitor{out};
  visitor.emit(defaults.stages);
  root["stages"] = YAML::Load(out.c_str());
}

}  // namespace

// ---------------------------------------------------------------- validation

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
  {
    Checker::Scope s(c, "camera");
    camera.validate(c);
  }
  Checker::Scope s(c, "video");
  video.validate(c);
}

void CameraConfig::validate(Checker& c) const {
  const int given = !intrinsics.empty() + !calib_file.empty() + (fov_deg != 0);
  c.require(given <= 1, "intrinsics", intrinsics, "give one of camera.intrinsics, camera.calib_file or camera.fov_deg, not several");
  if (!intrinsics.empty()) {
    c.require(intrinsics.size() == 4, "intrinsics", intrinsics, "must be [fx, fy, cx, cy] in pixels of the original frames");
    if (intrinsics.size() == 4) {
      c.require(std::isfinite(intrinsics[0]) && std::isfinite(intrinsics[1]) && intrinsics[0] > 0 && intrinsics[1] > 0 &&
                    intrinsics[0] < 1e5 && intrinsics[1] < 1e5,
                "intrinsics", intrinsics, "fx and fy must be in (0, 1e5) pixels");
      c.require(std::isfinite(intrinsics[2]) && std::isfinite(intrinsics[3]) && intrinsics[2] >= 0 && intrinsics[3] >= 0,
                "intrinsics", intrinsics, "cx and cy must be finite and >= 0 (pixels of the original frames)");
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

// ---------------------------------------------------------------- entry points

Config parse_config(const std::string& yaml_text, const std::string& source,
                    const std::vector<std::string>& overrides) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::ParserException& e) {
    throw ConfigError(source + " line " + std::to_string(e.mark.line + 1) +
                      ": malformed YAML: " + e.msg);
  }
  if (root.IsNull()) root = YAML::Node(YAML::NodeType::Map);
  if (!root.IsMap())
    throw ConfigError(source + " line " + std::to_string(root.Mark().line + 1) + ": a config is a map of sections " +
                      "(model:, data:, loss:, stages:, ...), not a " + (root.IsSequence() ? "list" : "single value"));
  Config config;
  config.source = source;
  ParseContext ctx{source, &config.lines, {}};
  try {
    for (const auto& o : overrides) {
      if (o.rfind("stages", 0) == 0) materialise_default_stages(root);
      apply_override(root, o, ctx);
    }
    read_value(root, "", config, ctx);
  } catch (const YAML::Exception& e) {  // anything the checks above did not foresee, with the file
    throw ConfigError(source + (e.mark.is_null() ? "" : " line " + std::to_string(e.mark.line + 1)) + ": " + e.msg);
  }
  // Footage without a camera: the camera is learned (the resolved config, written into the run
  // folder, says so).
  if (!config.data.videos.empty() && !config.data.camera.given()) config.model.learn_intrinsics = true;
  config.validate();
  return config;
}

Config load_config(const std::string& path, const std::vector<std::string>& overrides) {
  std::ifstream in(path);
  if (!in) throw ConfigError(path + ": cannot open config file (does it exist?)");
  std::stringstream buffer;
  buffer << in.rdbuf();
  // An empty file would silently mean every default: the paper's 350k-iteration schedule on ./data.
  bool empty = true;
  try {
    empty = YAML::Load(buffer.str()).IsNull();
  } catch (const YAML::Exception&) {
    empty = false;  // malformed: parse_config says where
  }
  if (empty)
    throw ConfigError(path + ": the config is empty (no keys); an empty config would run the paper's full schedule " +
                      "with every default: start from a shipped one (configs/stage1.yaml, configs/demo.yaml)");
  return parse_config(buffer.str(), path, overrides);
}

std::string shipped_config_dir() {
  if (const char* env = std::getenv("GEO_CONFIG_DIR")) return env;
  // An installed tool: <prefix>/bin/geo_x -> <prefix>/share/geo/configs (cmake --install).
  std::error_code ec;
  const auto exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const auto installed = exe.parent_path().parent_path() / "share" / "geo" / "configs";
    if (std::filesystem::is_directory(installed, ec)) return installed.string();
  }
  return std::string(kSourceDir) + "/configs";
}

std::string resolve_config_path(const std::string& name) {
  std::error_code ec;
  if (fs::is_regular_file(name, ec)) {
    spdlog::info("config {}", fs::absolute(name, ec).string());
    return name;
  }
  if (fs::exists(name, ec)) throw ConfigError("config '" + name + "' " + unreadable_file_reason(name) + " (a YAML file is needed)");
  const fs::path dir = shipped_config_dir();
  // Only a bare name means a shipped config: a path with a folder that does not exist is a typo,
  // and silently training the shipped file of the same name would hide it.
  if (fs::path(name).has_parent_path())
    throw ConfigError("config '" + name + "' not found (a path with a folder is used as given; bare names such as "
                      "stage1.yaml are looked up in " + dir.string() + ")");
  std::vector<fs::path> candidates{dir / name};
  if (fs::path(name).extension() != ".yaml") candidates.push_back(dir / (name + ".yaml"));
  for (const auto& candidate : candidates)
    if (fs::is_regular_file(candidate, ec)) {
      spdlog::info("config {} (shipped)", candidate.string());
      return candidate.string();
    }
  throw ConfigError("config '" + name + "' not found: not a file here, nor '" + (dir / name).string() +
                    (fs::path(name).extension() == ".yaml" ? "" : "[.yaml]") + "' among the shipped configs");
}

namespace {

// Every leaf of a YAML tree under its dotted path (sequences of maps by index: stages[0].name); a
// list of scalars is one value.
void flatten(const YAML::Node& n, const std::string& path, std::map<std::string, std::string>& out) {
  if (n.IsMap()) {
    for (const auto& kv : n) flatten(kv.second, join(path, kv.first.as<std::string>()), out);
    return;
  }
  if (n.IsSequence() && std::any_of(n.begin(), n.end(), [](const YAML::Node& item) { return !item.IsScalar(); })) {
    for (size_t i = 0; i < n.size(); ++i) flatten(n[i], path + "[" + std::to_string(i) + "]", out);
    return;
  }
  YAML::Emitter e;
  e << YAML::Flow << n;
  out[path] = e.c_str();
}

}  // namespace

std::vector<std::string> config_differences(const std::string& yaml_a, const std::string& yaml_b,
                                            const std::vector<std::string>& ignore) {
  std::map<std::string, std::string> a, b;
  flatten(YAML::Load(yaml_a), "", a);
  flatten(YAML::Load(yaml_b), "", b);
  const auto ignored = [&](const std::string& key) {
    return std::any_of(ignore.begin(), ignore.end(), [&](const std::string& i) {
      return key == i || (key.rfind(i, 0) == 0 && (key[i.size()] == '.' || key[i.size()] == '['));
    });
  };
  std::set<std::string> keys;
  for (const auto& kv : a) keys.insert(kv.first);
  for (const auto& kv : b) keys.insert(kv.first);
  std::vector<std::string> out;
  for (const auto& k : keys) {
    if (ignored(k)) continue;
    const auto ia = a.find(k), ib = b.find(k);
    const std::string va = ia == a.end() ? "(none)" : ia->second, vb = ib == b.end() ? "(none)" : ib->second;
    if (va != vb) out.push_back(k + ": " + va + " vs " + vb);
  }
  return out;
}

std::string to_yaml(const Config& config) {
  YAML::Emitter out;
  EmitVisitor visitor{out};
  visitor.emit(const_cast<Config&>(config));  // fields() is shared with parsing; nothing is written
  return std::string(out.c_str()) + "\n";
}

}  // namespace geo
