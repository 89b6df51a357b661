// Checkpoint rotation, best files, latest, and resolving a checkpoint or run folder (train/checkpoints.h).
#include "train/checkpoints.h"
#include "pipeline/checkpoint.h"
#include "core/runtime.h"

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

void fill_state(torch::serialize::OutputArchive& a, int64_t stage, int64_t it) {
  TrainState s;
  s.stage = stage;
  s.iteration = it;
  s.best_score = 0.5;
  write_train_state(a, s);
}

TrainState state_of(const std::string& path) { return CheckpointFile(path).train_state(); }

TEST(CheckpointNames, RoundTrip) {
  EXPECT_EQ(checkpoint_name("stage-2", 42), "stage-2-00000042.pt");
  EXPECT_EQ(stage_of_checkpoint("stage-2-00000042.pt"), "stage-2");
  EXPECT_EQ(stage_of_checkpoint("best-s1.pt"), "");
  EXPECT_EQ(stage_of_checkpoint("latest"), "");
}

TEST(CheckpointManager, RotationKeepsBestFilesAndLatest) {
  const auto dir = test::fresh_dir("ckpt");
  {
    CheckpointManager m(RunFolder(dir), 2);
    EXPECT_EQ(m.latest(), "");
    m.save("s1", 1, true, [](auto& a) { fill_state(a, 0, 1); });
    m.save("s1", 2, false, [](auto& a) { fill_state(a, 0, 2); });
    m.save("s2", 1, false, [](auto& a) { fill_state(a, 1, 1); });
    m.save("s2", 2, true, [](auto& a) { fill_state(a, 1, 2); });
    EXPECT_EQ(m.latest(), dir + "/checkpoints/s2-00000002.pt");
  }
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir + "/checkpoints")) names.insert(e.path().filename().string());
  EXPECT_EQ(names, (std::set<std::string>{"best-s1.pt", "best-s2.pt", "latest", "s2-00000001.pt", "s2-00000002.pt"}));
  // best-s1.pt outlived the rotation of s1-00000001.pt, its content intact.
  EXPECT_EQ(state_of(dir + "/checkpoints/best-s1.pt").iteration, 1);
  EXPECT_EQ(resolve_checkpoint(dir), dir + "/checkpoints/best-s2.pt");
  // A resumed manager continues the rotation from the files present.
  CheckpointManager again(RunFolder(dir), 2);
  again.save("s2", 3, false, [](auto& a) { fill_state(a, 1, 3); });
  EXPECT_FALSE(fs::exists(dir + "/checkpoints/s2-00000001.pt"));
  EXPECT_TRUE(fs::exists(dir + "/checkpoints/s2-00000002.pt"));
}

// Names decide what rotates and what is cleaned up: a stage named "best_fit" keeps its checkpoints
// in the rotation (they are not best files), and only real temporary files are removed.
TEST(CheckpointManager, NamesDecideWhatRotatesAndWhatIsATemporaryFile) {
  EXPECT_TRUE(is_best_checkpoint_name("best-stage1.pt"));
  EXPECT_TRUE(is_best_checkpoint_name("best-best_fit.pt"));
  EXPECT_FALSE(is_best_checkpoint_name("best_fit-00000010.pt"));
  EXPECT_FALSE(is_best_checkpoint_name("best-x-00000010.pt"));  // stage "best-x"'s checkpoint
  EXPECT_FALSE(is_best_checkpoint_name("bestiary.pt"));
  EXPECT_TRUE(is_rotation_checkpoint_name("best_fit-00000010.pt"));
  EXPECT_FALSE(is_rotation_checkpoint_name("s1-0000010.pt"));
  EXPECT_TRUE(is_temporary_file_name("s1-00000002.pt.tmp.1234"));
  EXPECT_TRUE(is_temporary_file_name("best-s1.pt.tmp"));
  EXPECT_FALSE(is_temporary_file_name("notes.tmp.txt"));
  EXPECT_FALSE(is_temporary_file_name("my.tmp.backup.pt"));

  const auto dir = test::fresh_dir("ckpt_names");
  fs::create_directories(dir + "/checkpoints");
  for (const char* f : {"notes.tmp.txt", "s1-00000002.pt.tmp.1234", "best-s1.pt.tmp"})
    test::write_text(dir + "/checkpoints/" + f, "x");
  {
    CheckpointManager m(RunFolder(dir), 2);
    for (int64_t it = 1; it <= 3; ++it) m.save("best_fit", it, it == 1, [it](auto& a) { fill_state(a, 0, it); });
  }
  std::set<std::string> names;
  for (const auto& e : fs::directory_iterator(dir + "/checkpoints")) names.insert(e.path().filename().string());
  EXPECT_EQ(names, (std::set<std::string>{"best-best_fit.pt", "best_fit-00000002.pt", "best_fit-00000003.pt", "latest",
                                          "notes.tmp.txt"}));
  EXPECT_EQ(state_of(dir + "/checkpoints/best-best_fit.pt").iteration, 1);
}

TEST(CheckpointManager, AFailedWriteKeepsTheLastCheckpointAndLatest) {
  const auto dir = test::fresh_dir("ckpt_full");
  CheckpointManager m(RunFolder(dir), 3);
  m.save("s1", 1, true, [](auto& a) { fill_state(a, 0, 1); });
  // The disk is full for the next checkpoint (its temporary file is a link to /dev/full).
  const std::string next = dir + "/checkpoints/s1-00000002.pt";
  ASSERT_EQ(::symlink("/dev/full", (next + ".tmp." + std::to_string(::getpid())).c_str()), 0);
  GEO_EXPECT_THROW_WITH(m.save("s1", 2, true, [](auto& a) { fill_state(a, 0, 2); }), next, "No space left on device");
  EXPECT_EQ(m.latest(), dir + "/checkpoints/s1-00000001.pt");
  EXPECT_EQ(state_of(dir + "/checkpoints/best-s1.pt").iteration, 1);
  EXPECT_FALSE(fs::exists(next));
  for (const auto& e : fs::directory_iterator(dir + "/checkpoints"))
    EXPECT_EQ(e.path().string().find(".tmp"), std::string::npos) << e.path();
}

TEST(CheckpointManager, ATruncatedLatestNamesTheNewestReadableCheckpoint) {
  const auto dir = test::fresh_dir("ckpt_trunc");
  CheckpointManager m(RunFolder(dir), 5);
  m.save("s1", 1, false, [](auto& a) { fill_state(a, 0, 1); });
  const std::string last = m.save("s1", 2, false, [](auto& a) { fill_state(a, 0, 2); });
  EXPECT_NO_THROW(m.check_resumable(last));
  const std::string bytes = test::read_file(last);
  test::write_text(last, bytes.substr(0, bytes.size() / 2));  // a kill in the middle of a copy
  GEO_EXPECT_THROW_WITH(m.check_resumable(last), "cannot resume", last, "truncated",
                        "The newest readable checkpoint is s1-00000001.pt");
  test::write_text(dir + "/checkpoints/random.pt", "not a checkpoint");
  GEO_EXPECT_THROW_WITH(m.check_resumable(dir + "/checkpoints/random.pt"), "random.pt", "s1-00000001.pt");
}

TEST(ResolveCheckpoint, FilesFoldersAndErrors) {
  const auto dir = test::fresh_dir("resolve");
  const std::string missing = dir + "/nothing";
  GEO_EXPECT_THROW_WITH(resolve_checkpoint(missing), missing.c_str(), "does not exist");
  GEO_EXPECT_THROW_WITH(resolve_checkpoint(dir), "has no checkpoint");
  CheckpointManager m(RunFolder(dir), 3);
  m.save("s1", 4, true, [](auto& a) { fill_state(a, 0, 4); });
  m.save("s2", 1, false, [](auto& a) { fill_state(a, 1, 1); });
  // The last stage has no best yet (no validation): its latest checkpoint, not stage 1's best.
  EXPECT_EQ(resolve_checkpoint(dir), dir + "/checkpoints/s2-00000001.pt");
  EXPECT_EQ(resolve_checkpoint(dir + "/checkpoints/best-s1.pt"), dir + "/checkpoints/best-s1.pt");
  test::write_text(dir + "/checkpoints/latest", "s2-00000009.pt\n");
  GEO_EXPECT_THROW_WITH(resolve_checkpoint(dir), "s2-00000009.pt", "does not exist");
}

}  // namespace
}  // namespace geo
