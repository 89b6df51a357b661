#include "core/output_folder.h"

#include "core/files.h"

#include <filesystem>
#include <fstream>
#include <set>
#include <stdexcept>

namespace geo {
namespace fs = std::filesystem;

namespace {

// The names an earlier run's manifest lists (none without one).
std::set<std::string> manifest_names(const fs::path& file) {
  std::set<std::string> names;
  std::ifstream in(file);
  for (std::string line; std::getline(in, line);)
    if (!line.empty() && line.find('/') == std::string::npos && line != "." && line != "..") names.insert(line);
  return names;
}

// `a` and `b` name one folder (links and ../ followed; either may not exist yet).
bool same_folder(const fs::path& a, const fs::path& b) {
  std::error_code ec;
  if (fs::equivalent(a, b, ec)) return true;
  auto ca = fs::weakly_canonical(a, ec), cb = fs::weakly_canonical(b, ec);
  return (ca /= "").lexically_normal() == (cb /= "").lexically_normal();
}

}  // namespace

void check_output_folder(const std::string& folder, const std::string& option, bool force,
                         const std::vector<std::string>& frame_folders) {
  const std::string what = option + " '" + folder + "'";
  if (folder.empty()) throw std::runtime_error(option + " is empty: give the folder to write into");
  for (const auto& frames : frame_folders)
    if (!frames.empty() && same_folder(folder, frames))
      throw std::runtime_error(what + " is the folder the input's frames are read from ('" + frames +
                               "'): its outputs would be read as frames next time");
  if (!fs::exists(folder)) return;
  if (!fs::is_directory(folder)) throw std::runtime_error(what + " exists and is not a folder");
  if (!force && !fs::is_empty(folder))
    throw std::runtime_error(what + " is not empty (--force replaces this tool's earlier outputs there)");
}

int64_t prepare_output_folder(const std::string& folder, const std::string& option, const std::string& manifest,
                              const std::vector<std::string>& planned, bool force,
                              const std::vector<std::string>& frame_folders) {
  check_output_folder(folder, option, force, frame_folders);
  const std::string what = option + " '" + folder + "'";
  int64_t removed = 0;
  if (fs::exists(folder) && !fs::is_empty(folder)) {
    const fs::path dir(folder);
    const auto ours = manifest_names(dir / manifest);
    for (const auto& name : planned)
      if (!ours.count(name) && fs::exists(fs::symlink_status(dir / name)))
        throw std::runtime_error(what + " holds '" + name + "', which this tool did not write (no " + manifest +
                                 " there names it): move it away or write into another folder");
    for (const auto& name : ours)
      if (fs::is_regular_file(fs::symlink_status(dir / name))) removed += fs::remove(dir / name) ? 1 : 0;
  }
  fs::create_directories(folder);
  std::string list;
  for (const auto& name : planned) list += name + "\n";
  write_file_atomic((fs::path(folder) / manifest).string(), list);
  return removed;
}

}  // namespace geo
