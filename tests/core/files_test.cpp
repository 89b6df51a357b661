// Durable file writes: replaced atomically, and a failed write (here a full disk: /dev/full) names
// the path and the OS error and leaves the previous file as it was.
#include "core/files.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>

#include "test_util.h"

namespace geo {
namespace {

TEST(Files, AtomicWriteReplacesAndAFullDiskLeavesTheOldFile) {
  const auto dir = test::fresh_dir("files");
  const std::string path = dir + "/result.json";
  write_file_atomic(path, "first");
  write_file_atomic(path, "second");
  EXPECT_EQ(test::read_file(path), "second");
  // The temporary file of this process is a link to /dev/full: every write fails with ENOSPC.
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  ASSERT_EQ(::symlink("/dev/full", tmp.c_str()), 0);
  GEO_EXPECT_THROW_WITH(write_file_atomic(path, std::string(1 << 16, 'x')), path, "No space left on device",
                        "unchanged");
  EXPECT_EQ(test::read_file(path), "second");
  EXPECT_FALSE(std::filesystem::exists(std::filesystem::symlink_status(tmp)));  // cleaned up
  GEO_EXPECT_THROW_WITH(write_file_atomic(dir + "/missing/x.txt", "x"), dir + "/missing/x.txt", "No such file");
}

TEST(Files, OneLockHolderPerFolderAndReleasedWithIt) {
  const auto dir = test::fresh_dir("lock");
  {
    const FolderLock first(dir);
    GEO_EXPECT_THROW_WITH(FolderLock second(dir), dir, "is in use by process " + std::to_string(::getpid()),
                          "one geo_train per run folder");
  }
  EXPECT_NO_THROW(FolderLock again(dir));  // released with its holder (a crashed process's too)
}

}  // namespace
}  // namespace geo
