// Configs as YAML: parsing with its lines, emitting, --set overrides, differences, and the whole
// config's validation (each section's checks: core/config_<section>.cpp). Files: config_files.cpp.
#include "core/config.h"
#include "core/config_check.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>
#include <sstream>

namespace geo {

using namespace config_text;

namespace {

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

template <class T>
void read_value(const YAML::Node& node, const std::string& path, T& out, ParseContext& ctx);

template <class T>
const char* type_name();
template <>
const char* type_name<int>() {
  return "an integer";
}
template <>
const char* type_name<int64_t>() {
  return "an integer";
}
template <>
const char* type_name<double>() {
  return "a number";
}
template <>
const char* type_name<bool>() {
  return "a boolean (true/false)";
}
template <>
const char* type_name<std::string>() {
  return "a string";
}

template <class T>
void read_scalar(const YAML::Node& node, const std::string& path, T& out, ParseContext& ctx) {
  std::string shown = node.IsScalar() ? "'" + node.Scalar() + "'" : "a list or map";
  if (!node.IsScalar())
    throw ConfigError(ctx.where(path, node) + ": key '" + path + "' must be " + type_name<T>() + ", got " + shown);
  if constexpr (std::is_integral_v<T> && !std::is_same_v<T, bool>) {
    // Plain decimal only: yaml-cpp reads 010 as octal 8 and 0x10 as 16, which nobody means in a
    // count of iterations.
    const std::string& t = node.Scalar();
    const size_t digits = !t.empty() && (t[0] == '+' || t[0] == '-') ? 1 : 0;  // where the digits start
    const bool decimal = !t.empty() && t.size() > digits &&
                         t.find_first_not_of("0123456789", digits) == std::string::npos &&
                         (t.size() == digits + 1 || t[digits] != '0');
    if (!decimal)
      throw ConfigError(ctx.where(path, node) + ": key '" + path + "' must be " + type_name<T>() +
                        " written in decimal without leading zeros, got " + shown);
  }
  try {
    out = node.as<T>();
  } catch (const YAML::Exception&) {
    throw ConfigError(ctx.where(path, node) + ": key '" + path + "' must be " + type_name<T>() + ", got " + shown);
  }
  if constexpr (std::is_floating_point_v<T>) {
    if (!std::isfinite(out))
      throw ConfigError(ctx.where(path, node) + ": key '" + path + "' must be finite, got " + shown);
  }
}

struct ParseVisitor {
  const YAML::Node& node;
  std::string prefix;
  ParseContext& ctx;
  std::vector<std::string> known;

  template <class T>
  void operator()(const char* key, T& out) {
    known.emplace_back(key);
    const YAML::Node child = node[key];
    if (!child.IsDefined()) return;  // keep the default
    const std::string path = join(prefix, key);
    if (child.IsNull()) {
      // An empty section keeps its defaults; an empty value ("iterations:", "iterations: ~") is a
      // value left out by mistake, never silently the default.
      if constexpr (std::is_arithmetic_v<T> || std::is_same_v<T, std::string> || std::is_enum_v<T>)
        throw ConfigError(ctx.where(path, child) + ": key '" + path +
                          "' has no value (give one, or leave the key out " + "for the default)");
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
                          "' is given twice (lines " + std::to_string(seen[key]) + " and " + std::to_string(line) +
                          ")");
      if (std::find(known.begin(), known.end(), key) != known.end()) continue;
      std::string valid;
      for (const auto& k : known) valid += (valid.empty() ? "" : ", ") + k;
      throw ConfigError(ctx.where(join(prefix, key), kv.first) + ": unknown key '" + join(prefix, key) +
                        "' (valid keys here: " + valid + ")");
    }
  }
};

void read_value(const YAML::Node& n, const std::string& p, int& o, ParseContext& c) { read_scalar(n, p, o, c); }
void read_value(const YAML::Node& n, const std::string& p, int64_t& o, ParseContext& c) { read_scalar(n, p, o, c); }
void read_value(const YAML::Node& n, const std::string& p, double& o, ParseContext& c) { read_scalar(n, p, o, c); }
void read_value(const YAML::Node& n, const std::string& p, bool& o, ParseContext& c) { read_scalar(n, p, o, c); }
void read_value(const YAML::Node& n, const std::string& p, std::string& o, ParseContext& c) { read_scalar(n, p, o, c); }

template <class T>
void read_value(const YAML::Node& node, const std::string& path, std::vector<T>& out, ParseContext& ctx) {
  if (!node.IsSequence()) throw ConfigError(ctx.where(path, node) + ": key '" + path + "' must be a list");
  out.clear();
  for (size_t i = 0; i < node.size(); ++i) {
    T item{};
    const std::string item_path = path + "[" + std::to_string(i) + "]";
    ctx.record(item_path, node[i]);
    read_value(node[i], item_path, item, ctx);
    out.push_back(std::move(item));
  }
}

template <class E>
void read_enum(const YAML::Node& node, const std::string& path, E& out, ParseContext& ctx) {
  std::string name;
  read_scalar(node, path, name, ctx);
  for (const auto& n : enum_names(E{}))
    if (name == n.name) {
      out = n.value;
      return;
    }
  throw ConfigError(ctx.where(path, node) + ": key '" + path + "' must be one of " + valid_names<E>() + ", got '" +
                    name + "'");
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
template <class T>
void read_value(const YAML::Node& node, const std::string& path, T& out, ParseContext& ctx) {
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
  template <class T>
  void operator()(const char* key, T& value) {
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
  template <class T>
  void emit(std::vector<T>& v) {
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
  template <class T>
  void emit(T& s) {
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
    if (name.empty() || !std::all_of(name.begin(), name.end(),
                                     [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; }))
      throw bad("'" + name + "' is not a key name");
    if (std::all_of(name.begin(), name.end(), ::isdigit) && name.size() > 6)
      throw bad("index " + name + " is too large");
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
  if (eq == std::string::npos || eq == 0) throw ConfigError("--set '" + text + "': expected key.path=value");
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
                          "' does not exist (the list has " + std::to_string(node.IsSequence() ? node.size() : 0) +
                          " entries)");
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

// ---------------------------------------------------------------- entry points

Config parse_config(const std::string& yaml_text, const std::string& source,
                    const std::vector<std::string>& overrides) {
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::ParserException& e) {
    throw ConfigError(source + " line " + std::to_string(e.mark.line + 1) + ": malformed YAML: " + e.msg);
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

void Config::validate() const {
  Checker c(lines, source);
  c.section("model", model);
  c.section("data", data);
  c.section("loss", loss);
  c.require(!stages.empty(), "stages", stages.size(), "must list at least one stage");
  std::set<std::string> names;
  for (size_t i = 0; i < stages.size(); ++i) {
    const std::string key = "stages[" + std::to_string(i) + "]";
    c.section(key, stages[i]);
    Checker::Scope s(c, key);
    c.require(names.insert(stages[i].name).second, "name", stages[i].name, "stage names must be unique");
    c.require(stages[i].hold_masked == 0 || loss.automask, "hold_masked", stages[i].hold_masked,
              "needs loss.automask: true (it measures the share of pixels auto-masking leaves out)");
  }
  c.section("optimizer", optimizer);
  c.section("logging", logging);
  c.section("run", run);
  c.fail_if_any();
}

}  // namespace geo
