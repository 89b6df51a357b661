// Whole-loop behaviour on a tiny synthetic world: a run stopped abruptly (as by kill -9) and resumed
// logs exactly the losses of an uninterrupted run; bad configs stop before training naming the key;
// NaN steps never reach a checkpoint.
#include "data/synth_writer.h"
#include "train/trainer.h"

#include <gtest/gtest.h>

#include "synth_world.h"

namespace geo {
namespace {

// One tiny world for the whole suite.
const std::string& world() {
  static const std::string root = test::write_small_world("trainer_world", 10, 0, 5) + "/raw";
  return root;
}

Config tiny_config(const std::string& extra = "") {
  return parse_config(R"(
model: {encoder_depth: 18}
data: {height: 64, width: 208, num_workers: 1, augment: {enabled: true}}
stages:
  - {name: s1, iterations: 3, train: [depth, pose], batch_size: 1}
  - {name: s2, iterations: 3, train: [depth, pose, flow], batch_size: 1}
logging: {interval: 1, summary_interval: 0, checkpoint_interval: 2, val_interval: 0, keep_last: 5}
run: {threads: 2, seed: 3}
)" + extra, "tiny.yaml", {"data.root=" + world()});
}

std::string metrics(const std::string& dir) { return test::read_file(dir + "/metrics.csv"); }

TEST(Trainer, KilledAndResumedRunLogsTheSameLosses) {
  const auto base = test::fresh_dir("resume");
  TrainOptions a;
  a.run_dir = base + "/whole";
  ASSERT_EQ(train(tiny_config(), a), 0);
  TrainOptions b;
  b.run_dir = base + "/killed";
  b.stop_after = 5;  // s1: 3 steps (checkpoints 2, 3), s2: 2 steps (checkpoint 2), then "killed"
  EXPECT_EQ(train(tiny_config(), b), 137);
  EXPECT_EQ(test::read_file(b.run_dir + "/checkpoints/latest"), "s2-00000002.pt\n");
  ASSERT_EQ(resume(b.run_dir, {}), 0);
  const auto whole = metrics(a.run_dir), resumed = metrics(b.run_dir);
  EXPECT_EQ(std::count(whole.begin(), whole.end(), '\n'), 7);  // header + 6 iterations
  EXPECT_EQ(whole, resumed);
}

TEST(Trainer, BadConfigStopsBeforeTrainingNamingTheKey) {
  auto cfg = tiny_config();
  cfg.data.root = "/nonexistent/kitti";
  TrainOptions o;
  o.run_dir = test::fresh_dir("badroot") + "/run";
  GEO_EXPECT_THROW_WITH(train(cfg, o), "data.root", "/nonexistent/kitti");
  EXPECT_FALSE(std::filesystem::exists(o.run_dir + "/checkpoints/latest"));
  GEO_EXPECT_THROW_WITH(tiny_config("optimizer: {beta3: 1}\n"), "optimizer.beta3");
}

TEST(Trainer, NonFiniteStepsAreSkippedAndStopTheRun) {
  // An absurd learning rate breaks the weights after the first update; later losses are NaN/Inf.
  auto cfg = tiny_config("optimizer: {eps: 1.0e-30}\n");
  cfg.stages.resize(1);
  cfg.stages[0].learning_rate = 1e30;
  cfg.stages[0].iterations = 50;
  cfg.logging.checkpoint_interval = 1;
  cfg.logging.max_bad_steps = 2;
  TrainOptions o;
  o.run_dir = test::fresh_dir("nan") + "/run";
  GEO_EXPECT_THROW_WITH(train(cfg, o), "NaN/Inf steps in a row", "logging.max_bad_steps");
  // Every checkpoint written holds finite weights.
  for (const auto& e : std::filesystem::directory_iterator(o.run_dir + "/checkpoints")) {
    if (e.path().extension() != ".pt") continue;
    torch::serialize::InputArchive a, depth;
    a.load_from(e.path().string());
    ASSERT_TRUE(a.try_read("depth", depth));
    for (const auto& key : depth.keys()) {
      torch::Tensor t;
      depth.read(key, t);
      EXPECT_TRUE(torch::isfinite(t).all().item<bool>()) << e.path() << " " << key;
    }
  }
}

}  // namespace
}  // namespace geo
