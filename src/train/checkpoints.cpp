#include "train/checkpoints.h"

#include "core/files.h"
#include "core/state_io.h"
#include "pipeline/checkpoint.h"

#include <algorithm>
#include <filesystem>
#include <stdexcept>
#include <system_error>

namespace fs = std::filesystem;

namespace geo {

CheckpointManager::CheckpointManager(RunFolder folder, int keep_last, bool read_only)
    : folder_(std::move(folder)), keep_last_(std::max(1, keep_last)) {
  if (read_only) return;
  fs::create_directories(this->dir());
  // Temporary files of an interrupted write (the run folder's lock is held, so none is in use).
  for (const auto& folder : {folder_.root(), this->dir()})
    for (const auto& e : fs::directory_iterator(folder))
      if (e.is_regular_file() && is_temporary_file_name(e.path().filename().string())) fs::remove(e.path());
  std::vector<std::pair<fs::file_time_type, std::string>> found;
  for (const auto& e : fs::directory_iterator(this->dir())) {
    const std::string name = e.path().filename().string();
    if (is_rotation_checkpoint_name(name)) found.emplace_back(e.last_write_time(), name);
  }
  std::sort(found.begin(), found.end());
  for (const auto& f : found) kept_.push_back(f.second);
}

std::string CheckpointManager::save(const std::string& stage, int64_t iteration, bool best,
                                    const std::function<void(torch::serialize::OutputArchive&)>& fill) {
  torch::serialize::OutputArchive archive;
  fill(archive);
  const std::string name = checkpoint_name(stage, iteration);
  const std::string path = folder_.checkpoint(stage, iteration);
  save_archive(archive, path);
  if (best) {
    // A new name for the same file, swapped into place: rotation deleting <stage>-<it>.pt later
    // leaves best-<stage>.pt whole, and no second copy of the weights is written.
    const std::string best_path = folder_.best(stage), best_tmp = best_path + ".tmp";
    fs::remove(best_tmp);
    std::error_code ec;
    fs::create_hard_link(path, best_tmp, ec);
    if (ec) fs::copy_file(path, best_tmp, fs::copy_options::overwrite_existing);
    fs::rename(best_tmp, best_path);
  }
  write_file_atomic(folder_.latest_pointer(), name + "\n");
  kept_.erase(std::remove(kept_.begin(), kept_.end(), name), kept_.end());
  kept_.push_back(name);
  while (static_cast<int>(kept_.size()) > keep_last_) {
    fs::remove(dir() + "/" + kept_.front());
    kept_.erase(kept_.begin());
  }
  return path;
}

std::string CheckpointManager::latest() const { return folder_.latest(); }

void CheckpointManager::check_resumable(const std::string& path) const {
  auto readable = [](const std::string& p, std::string* why) {
    try {
      CheckpointFile(p).train_state();
      return true;
    } catch (const std::exception& e) {
      if (why) *why = e.what();
      return false;
    }
  };
  std::string why;
  if (readable(path, &why)) return;
  std::vector<std::pair<fs::file_time_type, std::string>> others;
  for (const auto& e : fs::directory_iterator(dir()))
    if (is_rotation_checkpoint_name(e.path().filename().string()) && e.path().string() != path)
      others.emplace_back(e.last_write_time(), e.path().filename().string());
  std::sort(others.rbegin(), others.rend());
  std::string offer = " No other checkpoint in " + dir() + " is readable.";
  for (const auto& [t, name] : others)
    if (readable(dir() + "/" + name, nullptr)) {
      offer = " The newest readable checkpoint is " + name + ": to resume from it, write its name into " + dir() +
              "/latest.";
      break;
    }
  throw std::runtime_error("cannot resume: checkpoints/latest names a checkpoint that cannot be used: " + why + "." +
                           offer);
}

}  // namespace geo
