// The checkpoints of a run folder: written atomically, rotated, the best of each stage kept, and a
// run folder resolved to the checkpoint evaluation should use. LibTorch only.
//
//   checkpoints/<stage>-<iteration>.pt   networks, Adam state, train state, config (last keep_last kept)
//   checkpoints/best-<stage>.pt          the stage's checkpoint with the lowest validation score (a
//                                        hard link to it, so rotation never deletes it; a copy where
//                                        the file system has no links)
//   checkpoints/latest                   the name of the newest checkpoint
#pragma once

#include <torch/torch.h>

#include <functional>
#include <limits>
#include <string>
#include <vector>

namespace geo {

// Where training stands; stored in every checkpoint ("meta": float64 [stage, iteration, best]).
struct TrainState {
  int64_t stage = 0;       // index into the config's stages
  int64_t iteration = 0;   // iterations done in that stage
  double best_score = std::numeric_limits<double>::infinity();  // the stage's best validation score
};

void write_train_state(torch::serialize::OutputArchive& archive, const TrainState& state);
TrainState read_train_state(torch::serialize::InputArchive& archive, const std::string& source);

// "<stage>-<iteration, 8 digits>.pt"
std::string checkpoint_name(const std::string& stage, int64_t iteration);
// The stage part of a checkpoint name ("s2-00000004.pt" -> "s2"); "" if it is not one.
std::string stage_of_checkpoint(const std::string& name);

class CheckpointManager {
 public:
  // `dir`: the run folder (checkpoints/ is created). Existing checkpoints there (a resumed run) take
  // part in rotation, oldest first; temporary files left by an interrupted write are removed (hold
  // the run folder's FolderLock first).
  // `read_only` (the other ranks of a distributed run): nothing is created, removed or written.
  CheckpointManager(std::string dir, int keep_last, bool read_only = false);

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
  std::string dir() const { return dir_ + "/checkpoints"; }

 private:
  std::string dir_;
  int keep_last_;
  std::vector<std::string> kept_;  // rotation order, oldest first
};

// The checkpoint a path names: a .pt file as given; a run folder -> the best checkpoint of the stage
// its latest checkpoint belongs to (best-<stage>.pt), else that latest checkpoint. Throws naming the
// path when there is none.
std::string resolve_checkpoint(const std::string& path);

}  // namespace geo
