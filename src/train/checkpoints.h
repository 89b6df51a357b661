// The checkpoints of a run folder, written atomically and rotated, the best of each stage kept (the
// file format: pipeline/checkpoint.h; the folder's layout: pipeline/run_folder.h). LibTorch only.
#pragma once

#include "pipeline/checkpoint.h"

#include <torch/torch.h>

#include <functional>
#include <string>
#include <vector>

namespace geo {

class CheckpointManager {
 public:
  // `folder`: the run's folder (checkpoints/ is created). Existing checkpoints there (a resumed run) take
  // part in rotation, oldest first; temporary files left by an interrupted write are removed (hold
  // the run folder's FolderLock first).
  // `read_only` (the other ranks of a distributed run): nothing is created, removed or written.
  CheckpointManager(RunFolder folder, int keep_last, bool read_only = false);

  // Writes checkpoints/<stage>-<iteration>.pt through a temporary file, makes it best-<stage>.pt
  // when `best`, then points `latest` at it, and deletes the oldest beyond keep_last. A crash at any
  // point leaves `latest` naming a complete file. Returns the path written.
  std::string save(const std::string& stage, int64_t iteration, bool best,
                   const std::function<void(torch::serialize::OutputArchive&)>& fill);

  // checkpoints/<latest>, or "" when no checkpoint was written yet.
  std::string latest() const;
  // Throws unless `path` opens as a geo checkpoint; the message names the newest other checkpoint
  // that does (a resume can continue from it).
  void check_resumable(const std::string& path) const;
  std::string dir() const { return folder_.checkpoints(); }

 private:
  RunFolder folder_;
  int keep_last_;
  std::vector<std::string> kept_;  // rotation order, oldest first
};

}  // namespace geo
