// Config files: reading one, finding the shipped ones, and what a config makes a command read.
#include <spdlog/spdlog.h>
#include <yaml-cpp/yaml.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "core/config.h"
#include "core/files.h"
#include "core/paths.h"  // generated: GEO_SOURCE_DIR

namespace geo {
namespace fs = std::filesystem;

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
  if (fs::exists(name, ec))
    throw ConfigError("config '" + name + "' " + unreadable_file_reason(name) + " (a YAML file is needed)");
  const fs::path dir = shipped_config_dir();
  // Only a bare name means a shipped config: a path with a folder that does not exist is a typo,
  // and silently training the shipped file of the same name would hide it.
  if (fs::path(name).has_parent_path())
    throw ConfigError("config '" + name +
                      "' not found (a path with a folder is used as given; bare names such as "
                      "stage1.yaml are looked up in " +
                      dir.string() + ")");
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

std::vector<std::string> config_reads(const Config& c) {
  const auto& d = c.data;
  std::vector<std::string> reads = {d.root, d.train_list, d.val_list, d.camera.calib_file};
  if (!c.source.empty() && c.source.front() != '<') reads.push_back(c.source);
  reads.insert(reads.end(), d.videos.begin(), d.videos.end());
  for (const auto& s : c.stages) reads.push_back(s.init);
  return reads;
}

}  // namespace geo
