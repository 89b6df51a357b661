#include "pipeline/run_folder.h"

#include "core/files.h"

#include <algorithm>
#include <cctype>
#include <chrono>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <stdexcept>

namespace fs = std::filesystem;

namespace geo {

RunFolder RunFolder::create_new(const std::string& parent, const std::string& name) {
  const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", std::localtime(&now));
  fs::create_directories(parent);
  const fs::path base = fs::path(parent) / (name + "-" + stamp);
  fs::path dir = base;
  for (int k = 2; !fs::create_directory(dir); ++k) dir = base.string() + "-" + std::to_string(k);
  return RunFolder(dir.string());
}

std::string RunFolder::summary(const std::string& stage, int64_t iteration, const std::string& tag) const {
  return summaries() + "/" + stage + "-" + std::to_string(iteration) + "-" + tag + ".png";
}

std::string RunFolder::checkpoint(const std::string& stage, int64_t iteration) const {
  return checkpoints() + "/" + checkpoint_name(stage, iteration);
}

std::string RunFolder::best(const std::string& stage) const { return checkpoints() + "/best-" + stage + ".pt"; }

std::string RunFolder::latest() const {
  const std::string name = latest_checkpoint_name(checkpoints());
  return name.empty() ? "" : checkpoints() + "/" + name;
}

std::string RunFolder::resolve() const {
  const std::string latest = latest_checkpoint_name(checkpoints());
  if (latest.empty())
    throw std::runtime_error("run folder '" + root_ + "' has no checkpoint (checkpoints/latest missing or empty)");
  const std::string stage = stage_of_checkpoint(latest);
  if (!stage.empty() && fs::is_regular_file(best(stage))) return best(stage);
  const std::string file = checkpoints() + "/" + latest;
  if (!fs::is_regular_file(file))
    throw std::runtime_error("run folder '" + root_ + "': checkpoints/latest names " + latest +
                             ", which does not exist");
  return file;
}

std::vector<std::string> RunFolder::run_files() const {
  std::vector<std::string> found;
  for (const std::string& path : {config(), metrics_csv(), validation_csv(), clips(), log(), checkpoints()})
    if (fs::exists(path)) found.push_back(fs::path(path).filename().string());
  return found;
}

std::string checkpoint_name(const std::string& stage, int64_t iteration) {
  return stage + "-" + zero_padded(iteration, 8) + ".pt";
}

std::string stage_of_checkpoint(const std::string& name) {
  return is_rotation_checkpoint_name(name) ? name.substr(0, name.size() - 12) : "";
}

bool is_rotation_checkpoint_name(const std::string& name) {
  // <stage>-NNNNNNNN.pt: a non-empty stage name, '-', eight digits, ".pt".
  const size_t n = name.size();
  if (n < 13 || name.compare(n - 3, 3, ".pt") != 0 || name[n - 12] != '-') return false;
  for (size_t i = n - 11; i < n - 3; ++i)
    if (name[i] < '0' || name[i] > '9') return false;
  return true;
}

bool is_best_checkpoint_name(const std::string& name) {
  // best-<stage>.pt; a stage named "best..." has rotation checkpoints "best...-NNNNNNNN.pt", not best.
  return name.size() > 8 && name.rfind("best-", 0) == 0 && name.compare(name.size() - 3, 3, ".pt") == 0 &&
         !is_rotation_checkpoint_name(name);
}

bool is_temporary_file_name(const std::string& name) {
  // <file>.tmp (best-<stage>.pt.tmp) or <file>.tmp.<pid> (write_file_durable's).
  const size_t at = name.rfind(".tmp");
  if (at == std::string::npos || at == 0) return false;
  if (at + 4 == name.size()) return true;
  if (name[at + 4] != '.' || at + 5 == name.size()) return false;
  return name.find_first_not_of("0123456789", at + 5) == std::string::npos;
}

std::string latest_checkpoint_name(const std::string& checkpoints_dir) {
  std::ifstream in(checkpoints_dir + "/latest");
  std::string line;
  std::getline(in, line);
  return line;
}

std::string resolve_checkpoint(const std::string& path) {
  if (fs::is_regular_file(path)) return path;
  if (!fs::is_directory(path)) throw std::runtime_error("checkpoint '" + path + "' does not exist");
  return RunFolder(path).resolve();
}

}  // namespace geo
