// Durable file writes: replaced atomically, and a failed write (here a full disk: /dev/full) names
// the path and the OS error and leaves the previous file as it was.
#include "core/files.h"

#include <gtest/gtest.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <thread>

#include "test_util.h"

namespace geo {
namespace {

// A write of `path` on a full disk (this process's temporary file a link to /dev/full: every write
// fails with ENOSPC) names the path and the error, leaves `content` where it was and cleans up.
void expect_full_disk_leaves(const std::string& path, const std::string& content) {
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  ASSERT_EQ(::symlink("/dev/full", tmp.c_str()), 0);
  GEO_EXPECT_THROW_WITH(write_file_atomic(path, std::string(1 << 16, 'x')), path, "No space left on device",
                        "unchanged");
  EXPECT_EQ(test::read_file(path), content);
  EXPECT_FALSE(std::filesystem::exists(std::filesystem::symlink_status(tmp)));  // cleaned up
}

TEST(Files, AtomicWriteReplacesAndAFullDiskLeavesTheOldFile) {
  const auto dir = test::fresh_dir("files");
  const std::string path = dir + "/result.json";
  write_file_atomic(path, "first");
  write_file_atomic(path, "second");
  EXPECT_EQ(test::read_file(path), "second");
  expect_full_disk_leaves(path, "second");
  GEO_EXPECT_THROW_WITH(write_file_atomic(dir + "/missing/x.txt", "x"), dir + "/missing/x.txt", "No such file");
}

// Under DeferredSync files are still replaced atomically and a failed write still leaves the old
// file; commit() flushes (folders written into and removed since are passed over), and nested ones
// and writes after the last one ends work as before.
TEST(Files, DeferredSyncStillReplacesAtomicallyAndCommits) {
  const auto dir = test::fresh_dir("files_deferred");
  const std::string path = dir + "/0000-depth.png";
  {
    DeferredSync outer;
    write_file_atomic(path, "first");
    {
      DeferredSync inner;
      write_file_atomic(path, "second");
      std::filesystem::create_directories(dir + "/gone");
      write_file_atomic(dir + "/gone/x.txt", "x");
      std::filesystem::remove_all(dir + "/gone");
    }
    EXPECT_EQ(test::read_file(path), "second");
    expect_full_disk_leaves(path, "second");
    EXPECT_NO_THROW(outer.commit());
    write_file_atomic(path, "third");
    EXPECT_NO_THROW(outer.commit());
  }
  EXPECT_EQ(test::read_file(path), "third");
  write_file_atomic(path, "fourth");  // durable file by file again
  EXPECT_EQ(test::read_file(path), "fourth");
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), std::filesystem::directory_iterator()), 1);
}

// What is not a regular file is never replaced by one: a symbolic link is followed (its target is
// replaced, the link stays), a FIFO or a device is written into (and its errors reported), the
// process's own descriptors (/dev/fd/N) are written into, a folder is refused.
TEST(Files, AtomicWriteFollowsLinksAndWritesIntoDevicesAndFifos) {
  namespace fs = std::filesystem;
  const auto dir = test::fresh_dir("files_special");
  write_file_atomic(dir + "/target.json", "old");
  fs::create_symlink("target.json", dir + "/link.json");  // relative, as `ln -s` makes them
  write_file_atomic(dir + "/link.json", "new");
  EXPECT_TRUE(fs::is_symlink(fs::symlink_status(dir + "/link.json")));
  EXPECT_EQ(test::read_file(dir + "/target.json"), "new");
  fs::create_symlink(dir + "/not-yet.json", dir + "/dangling.json");  // a link to a file to be made
  write_file_atomic(dir + "/dangling.json", "made");
  EXPECT_TRUE(fs::is_symlink(fs::symlink_status(dir + "/dangling.json")));
  EXPECT_EQ(test::read_file(dir + "/not-yet.json"), "made");

  const std::string fifo = dir + "/pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  std::string received;
  std::thread reader([&] { received = test::read_file(fifo); });
  write_file_atomic(fifo, "through the pipe");
  reader.join();
  EXPECT_EQ(received, "through the pipe");
  EXPECT_TRUE(fs::is_fifo(fs::status(fifo)));

  // A descriptor path: what a shell's `> file` opened keeps receiving what is written.
  const std::string redirected = dir + "/redirected.txt";
  const int fd = ::open(redirected.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::write(fd, "log line\n", 9), 9);
  write_file_atomic("/dev/fd/" + std::to_string(fd), "via the descriptor");
  ASSERT_EQ(::write(fd, "\n", 1), 1);
  ::close(fd);
  EXPECT_EQ(test::read_file(redirected), "log line\nvia the descriptor\n");

  if (fs::is_character_file("/dev/full")) {
    GEO_EXPECT_THROW_WITH(write_file_atomic("/dev/full", "x"), "/dev/full", "No space left on device");
    EXPECT_TRUE(fs::is_character_file("/dev/full"));  // still the device, also for root
  }
  GEO_EXPECT_THROW_WITH(write_file_atomic(dir, "x"), dir, "is a folder");
  EXPECT_TRUE(fs::is_directory(dir));
}

// remove_tree: nested folders, files and links go, what the links point to outside stays; a missing
// path is nothing to do.
TEST(Files, RemoveTreeRemovesFoldersButNotWhatLinksPointTo) {
  namespace fs = std::filesystem;
  const auto dir = test::fresh_dir("remove_tree");
  fs::create_directories(dir + "/tree/a/b");
  write_file_atomic(dir + "/tree/a/b/x.txt", "x");
  write_file_atomic(dir + "/tree/y.txt", "y");
  write_file_atomic(dir + "/kept.txt", "kept");
  fs::create_directories(dir + "/kept_dir");
  write_file_atomic(dir + "/kept_dir/z.txt", "z");
  fs::create_symlink(dir + "/kept.txt", dir + "/tree/a/file_link");
  fs::create_directory_symlink(dir + "/kept_dir", dir + "/tree/dir_link");
  EXPECT_TRUE(remove_tree(dir + "/tree"));
  EXPECT_FALSE(fs::exists(fs::symlink_status(dir + "/tree")));
  EXPECT_EQ(test::read_file(dir + "/kept.txt"), "kept");
  EXPECT_EQ(test::read_file(dir + "/kept_dir/z.txt"), "z");
  EXPECT_TRUE(remove_tree(dir + "/tree"));      // already gone
  EXPECT_TRUE(remove_tree(dir + "/kept.txt"));  // a single file
  EXPECT_FALSE(fs::exists(dir + "/kept.txt"));
  // What cannot be removed, even by root (procfs entries): false, the entry and the OS error named.
  std::string error;
  EXPECT_FALSE(remove_tree("/proc/self/fd", &error));
  EXPECT_EQ(error.rfind("/proc/self/fd", 0), 0u) << error;
  EXPECT_NE(error.find(": "), std::string::npos) << error;
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

namespace geo {
namespace {

// One rule for every tool that writes results (geo_eval, geo_bench): nothing it reads, no two
// outputs on one path, no model or checkpoint without force; new files anywhere else are fine.
TEST(CheckOutputs, NeverOverInputsOrEachOtherOrAModel) {
  const auto dir = test::fresh_dir("check_outputs");
  test::write_text(dir + "/model.pt", std::string("PK\x03\x04", 4) + "rest of a zip archive");
  test::write_text(dir + "/data/poses/09.txt", "1 0 0 0 0 1 0 0 0 0 1 0\n");
  test::write_text(dir + "/old.json", "{}");
  const std::vector<std::string> inputs{dir + "/model.pt", dir + "/data"};
  EXPECT_NO_THROW(check_outputs({{"--output", dir + "/new.json"}, {"--output-poses", ""}}, inputs));
  EXPECT_NO_THROW(check_outputs({{"--output", dir + "/old.json"}}, inputs));           // an earlier result: replaced
  EXPECT_NO_THROW(check_outputs({{"--output", dir + "/data/results.json"}}, inputs));  // new, beside the data
  GEO_EXPECT_THROW_WITH(check_outputs({{"--output", dir + "/a.json"}, {"--output-poses", dir + "/./a.json"}}, inputs),
                        "--output and --output-poses name one file");
  GEO_EXPECT_THROW_WITH(check_outputs({{"--output", dir + "/model.pt"}}, inputs),
                        "--output '" + dir + "/model.pt' is '" + dir + "/model.pt', which this command reads");
  GEO_EXPECT_THROW_WITH(check_outputs({{"--output-poses", dir + "/data/poses/09.txt"}}, inputs),
                        "is a file inside '" + dir + "/data', which this command reads");
  test::write_text(dir + "/other.pt", std::string("PK\x03\x04", 4));
  GEO_EXPECT_THROW_WITH(check_outputs({{"--json", dir + "/other.pt"}}, inputs),
                        "--json '" + dir + "/other.pt' is a model or checkpoint");
  EXPECT_NO_THROW(check_outputs({{"--json", dir + "/other.pt"}}, inputs, true));
}

}  // namespace
}  // namespace geo
