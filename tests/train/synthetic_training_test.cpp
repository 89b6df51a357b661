// The training loop on the synthetic world rendered in memory (data.format synthetic): built and
// run in both builds; without OpenCV it is, with packed caches, the training data there is.
#include "core/config.h"
#include "data/training_data.h"
#include "train/trainer.h"

#include <gtest/gtest.h>

#include "test_util.h"
#include "train/training_helpers.h"
#ifdef GEO_WITH_OPENCV
#include "synth_world.h"
#endif

namespace geo {
namespace {

Config memory_config(const std::vector<std::string>& overrides = {}) {
  return parse_config(R"(
model: {encoder_depth: 18}
data:
  format: synthetic
  synthetic: {drives: 1, frames_per_drive: 10}
  height: 64
  width: 208
  num_workers: 1
stages:
  - {name: s1, iterations: 3, train: [depth, pose], batch_size: 1}
  - {name: s2, iterations: 2, train: [depth, pose, flow], batch_size: 1}
logging: {interval: 1, summary_interval: 2, checkpoint_interval: 2, val_interval: 2, keep_last: 5}
run: {threads: 2, seed: 3}
)",
                      "memory.yaml", overrides);
}

TEST(SyntheticTraining, KilledAndResumedRunLogsTheSameLosses) {
  // s1 done (checkpoints 2, 3), killed in s2.
  const auto r = test::killed_and_resumed(memory_config(), test::fresh_dir("synthetic_resume"), 4);
  EXPECT_EQ(r.latest_when_killed, "s1-00000003.pt\n");
  EXPECT_EQ(std::count(r.whole.begin(), r.whole.end(), '\n'), 6);  // header + 5 iterations
  EXPECT_EQ(r.whole, r.resumed);
  // Validation ran on the world's validation snippets (frame 5): one row per stage and interval.
  const auto val = test::read_file(r.whole_dir + "/val.csv");
  EXPECT_EQ(std::count(val.begin(), val.end(), '\n'), 4) << val;  // header + s1 at 2, 3 + s2 at 2
}

TEST(SyntheticTraining, NeedsNoFilesAndChecksItsKeys) {
  // data.root is not needed; the world's keys are checked by name.
  const auto data = open_training_data(memory_config().data);
  EXPECT_EQ(data.format, "synthetic");
  EXPECT_EQ(data.train->size(), 7u);  // targets 1..8, frame 5 to validation
  ASSERT_TRUE(data.val);
  EXPECT_EQ(data.val->size(), 1u);
  GEO_EXPECT_THROW_WITH(memory_config({"data.synthetic.preset=huge"}), "data.synthetic.preset", "tiny or kitti");
  GEO_EXPECT_THROW_WITH(memory_config({"data.synthetic.drives=0"}), "data.synthetic.drives");
  GEO_EXPECT_THROW_WITH(
      open_training_data(memory_config({"data.synthetic.frames_per_drive=4", "data.seq_length=5"}).data),
      "shorter than one snippet");
}

#ifdef GEO_WITH_OPENCV
// The same world read from geo_synth's PNG files trains to the same losses.
TEST(SyntheticTraining, TrainsAsOnGeoSynthsFiles) {
  const auto root = test::write_small_world("synthetic_files", 10, 0, 3) + "/raw";
  const auto base = test::fresh_dir("synthetic_vs_files");
  TrainOptions a, b;
  a.run_dir = base + "/memory";
  b.run_dir = base + "/files";
  ASSERT_EQ(train(memory_config(), a), 0);
  ASSERT_EQ(train(memory_config({"data.format=kitti_raw", "data.root=" + root}), b), 0);
  EXPECT_EQ(test::metrics(a.run_dir), test::metrics(b.run_dir));
}
#else
TEST(SyntheticTraining, ImageFoldersNeedABuildWithOpenCv) {
  const auto dir = test::fresh_dir("no_opencv_root");
  GEO_EXPECT_THROW_WITH(open_training_data(memory_config({"data.format=auto", "data.root=" + dir}).data),
                        "not a packed cache", "without OpenCV", "data.format: synthetic");
}
#endif

}  // namespace
}  // namespace geo
