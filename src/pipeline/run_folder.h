// A training run's folder: every path in it and the rules its file names follow. Nothing else
// spells these paths.
//
//   config.yaml                                the resolved config the run trains with
//   train.log                                  the log
//   metrics.csv, val.csv                       one row per iteration / per validation (train/metrics.h)
//   tb/events.out.tfevents.*                   TensorBoard
//   summaries/<stage>-<iteration>-<tag>.png    image summaries
//   checkpoints/<stage>-<iteration, 8 digits>.pt   training checkpoints (train/checkpoints.h rotates them)
//   checkpoints/best-<stage>.pt                the stage's checkpoint with the lowest validation score
//   checkpoints/latest                         the name of the newest checkpoint
//   anchor-<stage>.pt                          the DepthNet a stage started from (stages[].weights.anchor)
// A file whose write was interrupted is left as <file>.tmp or <file>.tmp.<pid>.
// LibTorch-free.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace geo {

class RunFolder {
 public:
  explicit RunFolder(std::string root) : root_(std::move(root)) {}
  // A new, empty folder <parent>/<name>-<YYYYmmdd-HHMMSS>[-<n>] (never one that exists).
  static RunFolder create_new(const std::string& parent, const std::string& name);

  const std::string& root() const { return root_; }
  std::string config() const { return root_ + "/config.yaml"; }
  std::string log() const { return root_ + "/train.log"; }
  std::string metrics_csv() const { return root_ + "/metrics.csv"; }
  std::string validation_csv() const { return root_ + "/val.csv"; }
  std::string clips() const { return root_ + "/clips.txt"; }  // data.videos: what each clip gave (resume checks it)
  std::string tensorboard() const { return root_ + "/tb"; }
  std::string summaries() const { return root_ + "/summaries"; }
  std::string summary(const std::string& stage, int64_t iteration, const std::string& tag) const;
  std::string checkpoints() const { return root_ + "/checkpoints"; }
  std::string checkpoint(const std::string& stage, int64_t iteration) const;
  std::string best(const std::string& stage) const;
  std::string latest_pointer() const { return checkpoints() + "/latest"; }
  std::string anchor(const std::string& stage) const { return root_ + "/anchor-" + stage + ".pt"; }

  // The newest checkpoint's path (from checkpoints/latest), "" when none was written.
  std::string latest() const;
  // What the folder stands for: the best checkpoint of the stage its latest checkpoint belongs to,
  // else that latest checkpoint. Throws naming the folder when there is none.
  std::string resolve() const;
  // The files of a run present here (config.yaml, logs, CSVs, checkpoints/): a new run refuses
  // such a folder, so that two runs never mix.
  std::vector<std::string> run_files() const;

 private:
  std::string root_;
};

// "<stage>-<iteration, 8 digits>.pt"
std::string checkpoint_name(const std::string& stage, int64_t iteration);
// The stage part of a checkpoint name ("s2-00000004.pt" -> "s2"); "" if it is not one.
std::string stage_of_checkpoint(const std::string& name);
// <stage>-NNNNNNNN.pt, the checkpoints that rotate.
bool is_rotation_checkpoint_name(const std::string& name);
// best-<stage>.pt files are links to a stage's best checkpoint, not checkpoints of their own.
bool is_best_checkpoint_name(const std::string& name);
// The temporary file of an interrupted write: <file>.tmp or <file>.tmp.<pid>; nothing else.
bool is_temporary_file_name(const std::string& name);
// The checkpoint name in <checkpoints_dir>/latest, or "" when there is none.
std::string latest_checkpoint_name(const std::string& checkpoints_dir);

// The checkpoint a path names: a file as given; a run folder -> RunFolder(path).resolve(). Throws
// naming the path when there is none.
std::string resolve_checkpoint(const std::string& path);

}  // namespace geo
