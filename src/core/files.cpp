#include "core/files.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <stdexcept>

namespace geo {
namespace fs = std::filesystem;

namespace {

std::string os_error() { return std::strerror(errno); }

// fsync of a folder, so that a rename inside it survives a power loss.
void sync_dir(const std::string& dir) {
  const int fd = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY);
  if (fd < 0) return;  // not fatal: some file systems do not open folders
  ::fsync(fd);
  ::close(fd);
}

}  // namespace

void write_file_durable(const std::string& path, const std::function<void(const ChunkWriter&)>& produce) {
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error("cannot write " + path + ": " + os_error() + " (opening " + tmp + ")");
  std::string error;
  const ChunkWriter write = [&](const void* data, size_t n) {
    const char* p = static_cast<const char*>(data);
    while (error.empty() && n > 0) {
      const ssize_t w = ::write(fd, p, n);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) {
        error = os_error();
        break;
      }
      p += w;
      n -= static_cast<size_t>(w);
    }
  };
  try {
    produce(write);
  } catch (...) {
    ::close(fd);
    ::unlink(tmp.c_str());
    throw;
  }
  if (error.empty() && ::fsync(fd) != 0) error = os_error();
  if (::close(fd) != 0 && error.empty()) error = os_error();
  if (error.empty() && ::rename(tmp.c_str(), path.c_str()) != 0) error = os_error() + " (renaming " + tmp + ")";
  if (!error.empty()) {
    ::unlink(tmp.c_str());
    throw std::runtime_error("cannot write " + path + ": " + error + "; the file that stood there is unchanged");
  }
  sync_dir(fs::path(path).parent_path().string());
}

void write_file_atomic(const std::string& path, const std::string& content) {
  write_file_durable(path, [&](const ChunkWriter& write) { write(content.data(), content.size()); });
}

FolderLock::FolderLock(const std::string& dir) {
  const std::string path = dir + "/.lock";
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) throw std::runtime_error("cannot lock " + dir + ": " + os_error() + " (" + path + ")");
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    char holder[256] = {0};
    const ssize_t n = ::pread(fd_, holder, sizeof holder - 1, 0);
    ::close(fd_);
    fd_ = -1;
    std::string who = n > 0 ? std::string(holder, static_cast<size_t>(n)) : "another process";
    while (!who.empty() && (who.back() == '\n' || who.back() == ' ')) who.pop_back();
    throw std::runtime_error(dir + " is in use by " + who + " (" + path +
                             "): one geo_train per run folder; wait for it or stop it first");
  }
  char host[256] = "localhost";
  ::gethostname(host, sizeof host - 1);
  const std::string me = "process " + std::to_string(::getpid()) + " on " + host + "\n";
  if (::ftruncate(fd_, 0) == 0 && ::pwrite(fd_, me.data(), me.size(), 0) < 0) {
    // the lock holds without the note; nothing to do
  }
}

FolderLock::~FolderLock() {
  if (fd_ >= 0) ::close(fd_);  // releases the lock
}

std::string make_run_dir(const std::string& parent, const std::string& name) {
  const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y%m%d-%H%M%S", std::localtime(&now));
  fs::create_directories(parent);
  const fs::path base = fs::path(parent) / (name + "-" + stamp);
  fs::path dir = base;
  for (int k = 2; !fs::create_directory(dir); ++k) dir = base.string() + "-" + std::to_string(k);
  return dir.string();
}

}  // namespace geo
