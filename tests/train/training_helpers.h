// Shared by the trainer tests: stopping a run from inside, reading what it logged.
#pragma once

#include "train/metrics.h"

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

}  // namespace geo::test
