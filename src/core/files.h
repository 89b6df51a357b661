// Files every run writes: atomic replacement and run folders.
#pragma once

#include <cstddef>
#include <functional>
#include <string>
#include <vector>

namespace geo {

// Receives the bytes of a file being written, chunk by chunk.
using ChunkWriter = std::function<void(const void* data, size_t size)>;

// Writes `path` durably: `produce` streams the bytes into a temporary file beside it, which is
// fsync'ed, renamed into place and its folder fsync'ed, so neither a crash nor a power loss leaves
// a half-written file where a good one stood. A failed write (disk full, read-only folder, quota)
// removes the temporary file, leaves the old file untouched and throws std::runtime_error naming
// the path and the OS error. A symbolic link is followed (the file it names is replaced, the link
// stays); devices, FIFOs, sockets and the process's descriptors (/dev/stdout) are written into, never
// replaced; a folder is refused.
void write_file_durable(const std::string& path, const std::function<void(const ChunkWriter&)>& produce);

// write_file_durable of a string.
void write_file_atomic(const std::string& path, const std::string& content);

// While one is alive (in any thread), write_file_durable still replaces files atomically (a
// temporary file renamed into place: a crash leaves the old file or the new one, never half of one)
// but does not wait for the disk file by file: commit() (and the end of its life) makes everything
// written since durable with one flush of each file system written to (syncfs). For tools that
// write many small outputs (geo_infer: three PNGs a frame, where a flush per file cost ~8 ms a frame
// on a virtual machine). Nested ones flush when the outermost ends.
class DeferredSync {
 public:
  DeferredSync();
  ~DeferredSync();
  DeferredSync(const DeferredSync&) = delete;
  DeferredSync& operator=(const DeferredSync&) = delete;
  // Flushes what was written so far; throws std::runtime_error naming a folder whose file system
  // could not be flushed (disk full, I/O error).
  void commit();
};

// The rule for every tool that writes results: never over a file the command reads (an input file,
// or an existing file inside an input folder such as a data root), never two outputs on one path,
// and never over a model or checkpoint (a zip archive) unless `force`. `outputs` pairs each option
// with its path (empty paths are skipped); throws std::runtime_error naming the option and the path.
struct NamedPath {
  std::string option, path;
};
void check_outputs(const std::vector<NamedPath>& outputs, const std::vector<std::string>& inputs, bool force = false);

// Why `path` cannot be read as a file: "" for a regular file (or a link to one), else "no such
// file", "is a folder, not a file", "is a FIFO (named pipe), not a file", "is a device, not a file",
// "is a socket, not a file". Every reader of a model, checkpoint or config says so by name instead of
// blocking on a FIFO or reading /dev/zero without end.
std::string unreadable_file_reason(const std::string& path);

// An exclusive lock on a folder (flock on <dir>/.lock, which holds the owner's PID and host): one
// writer per run folder. The kernel releases it when the process ends, however it ends, so a crash
// never leaves a stale lock. Throws std::runtime_error naming the holder when the folder is taken.
class FolderLock {
 public:
  explicit FolderLock(const std::string& dir);
  ~FolderLock();
  FolderLock(const FolderLock&) = delete;
  FolderLock& operator=(const FolderLock&) = delete;

 private:
  int fd_ = -1;
};

// Removes `path` and everything under it (a file, a link, which is not followed, or a folder);
// true when nothing is left there (also when nothing was). On failure returns false and, with
// `error`, says which entry and why. geo's own rather than std::filesystem::remove_all: PyTorch's
// pip LibTorch exports a copy of libstdc++'s filesystem functions that the dynamic linker binds
// ahead of libstdc++'s own, and its remove_all crashed (a call through a null pointer).
bool remove_tree(const std::string& path, std::string* error = nullptr);

// `number` in decimal with leading zeros to `digits` digits: KITTI's file names (000042.png,
// 0000000042.png) and checkpoint numbers.
std::string zero_padded(long long number, int digits);

}  // namespace geo
