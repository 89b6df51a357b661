// The training loop (reference.md Sec. 4, issue #7): the config's stages in order, Adam, optional
// step schedule and gradient clipping, checkpoints (networks, optimiser, counters, config) written
// atomically every N iterations and at the end of each stage, exact resumption, NaN/Inf steps
// skipped and counted, SIGINT/SIGTERM -> checkpoint and exit, progress lines, metrics.csv and
// val.csv per run, and PNG summaries (disparity, flow, occlusion, warped source).
//
// Run folder: config.yaml (resolved), train.log, metrics.csv (one row per iteration), val.csv,
// checkpoints/<stage>-<iteration>.pt (last keep_last kept), checkpoints/best.pt (lowest validation
// photometric loss), checkpoints/latest (name of the newest), summaries/*.png.
#pragma once

#include "core/config.h"

#include <cstdint>
#include <string>

namespace geo {

struct TrainOptions {
  std::string run_dir;        // run folder to create; empty = <run.dir>/<run.name>-<timestamp>
  std::string init;           // overrides stages[0].init (a checkpoint file or a run folder)
  std::string device;         // overrides run.device (auto | cpu | cuda)
  int64_t stop_after = -1;    // stop abruptly after this many steps, without a final checkpoint
                              // (what a kill does; for tests)
};

// Exit codes: 0 done, 130 interrupted by a signal (checkpoint written). Throws on errors.
int train(const Config& config, const TrainOptions& options, std::string* run_dir = nullptr);
// Continues the run in `run_dir` from its latest checkpoint, with the config stored there.
int resume(const std::string& run_dir, const TrainOptions& options);

// The checkpoint a path names: a .pt file, or a run folder (its best, else its latest checkpoint).
std::string resolve_checkpoint(const std::string& path);

}  // namespace geo
