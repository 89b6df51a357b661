// geo_train's loop (paper Sec. 4.2): the config's stages in order, each a TrainStep driven over the
// deterministic batch stream, with validation, checkpoints (CheckpointManager), metrics sinks (CSV,
// TensorBoard, console), PNG summaries, exact resumption, NaN/Inf steps skipped and counted, and
// SIGINT/SIGTERM -> checkpoint and exit 130.
//
// The run folder's layout: pipeline/run_folder.h.
#pragma once

#include "core/config.h"
#include "train/checkpoints.h"
#include "train/metrics.h"

#include <memory>
#include <string>
#include <vector>

namespace geo {

struct TrainOptions {
  std::string run_dir;      // run folder to create; empty = <run.dir>/<run.name>-<timestamp>
  std::string init;         // overrides stages[0].init (a checkpoint file or a run folder)
  std::string device;       // overrides run.device (auto | cpu | cuda | cuda:N)
  std::string master_addr;  // distributed under SLURM: the rendezvous host when MASTER_ADDR is unset
  // Extra receivers of every step, validation and summary image, after the built-in CSV,
  // TensorBoard and console sinks. An exception thrown by a sink stops the run at once, without a
  // checkpoint (as a crash would).
  std::vector<std::shared_ptr<MetricsSink>> sinks;
};

// Exit codes: 0 done, 130 interrupted by a signal (checkpoint written). Throws on errors.
// Training keeps freed memory in the process from then on (keep_freed_memory, core/runtime.h).
int train(const Config& config, const TrainOptions& options, std::string* run_dir = nullptr);
// Continues the run in `run_dir` from its latest checkpoint, with the config stored there.
int resume(const std::string& run_dir, const TrainOptions& options);

}  // namespace geo
