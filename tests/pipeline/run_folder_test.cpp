// The run folder's layout and new folders (pipeline/run_folder.h).
#include "pipeline/run_folder.h"

#include <ATen/autocast_mode.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <numeric>

#include <unistd.h>

#include "test_util.h"

namespace geo {
namespace {

namespace fs = std::filesystem;

// Every path of a run is the folder's: the layout written out here by hand.
TEST(RunFolder, PathsNewFoldersAndTheFilesOfARun) {
  const auto dir = test::fresh_dir("run_folder");
  const RunFolder f(dir + "/r");
  EXPECT_EQ(f.config(), dir + "/r/config.yaml");
  EXPECT_EQ(f.log(), dir + "/r/train.log");
  EXPECT_EQ(f.metrics_csv(), dir + "/r/metrics.csv");
  EXPECT_EQ(f.validation_csv(), dir + "/r/val.csv");
  EXPECT_EQ(f.tensorboard(), dir + "/r/tb");
  EXPECT_EQ(f.summary("stage2", 120, "flow"), dir + "/r/summaries/stage2-120-flow.png");
  EXPECT_EQ(f.checkpoint("stage2", 120), dir + "/r/checkpoints/stage2-00000120.pt");
  EXPECT_EQ(f.best("stage2"), dir + "/r/checkpoints/best-stage2.pt");
  EXPECT_EQ(f.latest_pointer(), dir + "/r/checkpoints/latest");
  EXPECT_EQ(f.latest(), "");
  EXPECT_TRUE(f.run_files().empty());
  fs::create_directories(f.checkpoints());
  test::write_text(f.metrics_csv(), "x\n");
  EXPECT_EQ(f.run_files(), (std::vector<std::string>{"metrics.csv", "checkpoints"}));
  test::write_text(f.latest_pointer(), "stage2-00000120.pt\n");
  EXPECT_EQ(f.latest(), f.checkpoint("stage2", 120));
  // New folders: <name>-<date>-<time>, never one that exists (a second in the same second gets -2).
  const RunFolder a = RunFolder::create_new(dir + "/runs", "demo"), b = RunFolder::create_new(dir + "/runs", "demo");
  EXPECT_NE(a.root(), b.root());
  EXPECT_TRUE(fs::is_directory(a.root()) && fs::is_directory(b.root()));
  EXPECT_EQ(fs::path(a.root()).filename().string().rfind("demo-", 0), 0u);
  EXPECT_EQ(fs::path(a.root()).filename().string().size(), std::string("demo-20261124-120000").size());
}

}  // namespace
}  // namespace geo
