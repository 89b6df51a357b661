// Shared by the trainer tests: killing a run for real (SIGKILL, in a child process), reading what it
// logged.
#pragma once

#include "core/config.h"
#include "train/metrics.h"
#include "train/trainer.h"

#include <gtest/gtest.h>

#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "process_util.h"
#include "test_util.h"

namespace geo::test {

// SIGKILLs this process once `n` steps are done (counted over all stages): no destructor, no
// flush, no checkpoint of the step it interrupts, as kill -9 or a power loss.
struct SigkillAtStep : MetricsSink {
  explicit SigkillAtStep(int64_t n) : left(n) {}
  void on_step(const StepRecord&) override {
    if (--left == 0) std::raise(SIGKILL);
  }
  int64_t left;
};

// The child side of train_until_killed: this test program started again with GEO_TEST_KILL_* set
// trains before running any test and never returns (killed; exit 2 on an error, 3 if the step never
// came).
class TrainUntilKilledChild : public ::testing::Environment {
 public:
  void SetUp() override {
    const char* config = std::getenv("GEO_TEST_KILL_CONFIG");
    if (!config) return;
    try {
      TrainOptions o;
      o.run_dir = std::getenv("GEO_TEST_KILL_RUN_DIR");
      o.device = std::getenv("GEO_TEST_KILL_DEVICE");
      o.init = std::getenv("GEO_TEST_KILL_INIT");
      o.sinks.push_back(std::make_shared<SigkillAtStep>(std::stoll(std::getenv("GEO_TEST_KILL_STEP"))));
      train(parse_config(read_file(config), config), o);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "train_until_killed child: %s\n", e.what());
      std::_Exit(2);
    }
    std::_Exit(3);
  }
};
inline ::testing::Environment* const train_until_killed_child =
    ::testing::AddGlobalTestEnvironment(new TrainUntilKilledChild);

inline std::string metrics(const std::string& dir) { return read_file(dir + "/metrics.csv"); }

// Trains `config` with `options` (no sinks) in a child process that is SIGKILLed at step `step`
// (counted over all stages); the run folder keeps what was written before it.
inline void train_until_killed(const Config& config, const TrainOptions& options, int64_t step) {
  ASSERT_TRUE(options.sinks.empty()) << "the killed run is another process: no sinks";
  const std::string yaml = options.run_dir + ".config.yaml", log = options.run_dir + ".log";
  write_text(yaml, to_yaml(config));
  Proc child = spawn(std::filesystem::read_symlink("/proc/self/exe").string(), {},
                     {{"GEO_TEST_KILL_CONFIG", yaml},
                      {"GEO_TEST_KILL_RUN_DIR", options.run_dir},
                      {"GEO_TEST_KILL_DEVICE", options.device},
                      {"GEO_TEST_KILL_INIT", options.init},
                      {"GEO_TEST_KILL_STEP", std::to_string(step)}},
                     log);
  EXPECT_EQ(wait_for(child, 900), 128 + SIGKILL) << read_file(log);
}

// The scenario the resumption tests share: `config` trained uninterrupted into <base>/whole and,
// from scratch, into <base>/killed, SIGKILLed at step `kill_at` and resumed there (`device` for
// both). What each logged, and the checkpoint the killed run left as latest.
struct KilledAndResumed {
  std::string whole_dir, killed_dir;
  std::string latest_when_killed;  // checkpoints/latest right after the kill
  std::string whole, resumed;      // metrics.csv of each
};
inline KilledAndResumed killed_and_resumed(const Config& config, const std::string& base, int64_t kill_at,
                                           const std::string& device = "") {
  KilledAndResumed r;
  TrainOptions a, b;
  a.run_dir = r.whole_dir = base + "/whole";
  b.run_dir = r.killed_dir = base + "/killed";
  a.device = b.device = device;
  EXPECT_EQ(train(config, a), 0);
  train_until_killed(config, b, kill_at);
  r.latest_when_killed = read_file(b.run_dir + "/checkpoints/latest");
  TrainOptions again;
  again.device = device;
  EXPECT_EQ(resume(b.run_dir, again), 0);
  r.whole = metrics(a.run_dir);
  r.resumed = metrics(b.run_dir);
  return r;
}

}  // namespace geo::test
