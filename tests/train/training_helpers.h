// Shared by the trainer tests: stopping a run from inside, reading what it logged.
#pragma once

#include "train/metrics.h"
#include "train/trainer.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <stdexcept>
#include <string>

#include "test_util.h"

namespace geo::test {

// Stops the run from inside, as a crash would: no checkpoint for the step it interrupts.
struct KillAtStep : MetricsSink {
  explicit KillAtStep(int64_t n) : left(n) {}
  void on_step(const StepRecord&) override {
    if (--left == 0) throw std::runtime_error("killed");
  }
  int64_t left;
};

inline std::string metrics(const std::string& dir) { return read_file(dir + "/metrics.csv"); }

// Trains `config` with `options` until a crash at step `step` (counted over all stages); the run
// folder keeps the checkpoints written before it.
inline void train_until_killed(const Config& config, TrainOptions options, int64_t step) {
  options.sinks.push_back(std::make_shared<KillAtStep>(step));
  GEO_EXPECT_THROW_WITH(train(config, options), "killed");
}

}  // namespace geo::test
