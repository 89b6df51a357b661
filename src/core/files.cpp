#include "core/files.h"

#include <fcntl.h>
#include <ftw.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <set>
#include <stdexcept>
#include <utility>

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

// DeferredSync's state: how many are alive, and the folders written into since the last flush.
std::mutex g_deferred_mutex;
int g_deferred = 0;
std::set<std::string> g_deferred_folders;

// True (and `dir` remembered for the flush) while a DeferredSync is alive.
bool defer_sync(const std::string& dir) {
  std::lock_guard<std::mutex> lock(g_deferred_mutex);
  if (g_deferred == 0) return false;
  g_deferred_folders.insert(dir.empty() ? "." : dir);
  return true;
}

// One syncfs per file system among `folders`; "" or the first folder that failed with its error.
std::string flush_file_systems(const std::set<std::string>& folders) {
  std::set<dev_t> done;
  for (const auto& dir : folders) {
    struct stat st {};
    if (::stat(dir.c_str(), &st) != 0 || !done.insert(st.st_dev).second) continue;  // (gone: nothing to keep)
    const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) continue;  // not fatal: some file systems do not open folders
    const int rc = ::syncfs(fd);
    const std::string error = rc != 0 ? os_error() : "";
    ::close(fd);
    if (rc != 0) return dir + ": " + error;
  }
  return "";
}

// Streams `produce` into an open descriptor; returns the first OS error ("" when none).
std::string stream_into(int fd, const std::function<void(const ChunkWriter&)>& produce) {
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
  produce(write);
  return error;
}

// The process's own descriptors: /dev/stdout, /dev/fd/N, /proc/self/fd/N (links to whatever the
// descriptor holds, which the process keeps writing to after a rename).
bool is_descriptor_path(const fs::path& p) {
  const std::string s = p.string();
  for (const char* prefix : {"/proc/", "/dev/fd/", "/dev/stdout", "/dev/stderr"})
    if (s.rfind(prefix, 0) == 0) return true;
  return false;
}

// A symbolic link's final target (relative links resolved against the link's folder), also when
// that target does not exist yet; `path` itself when it is no link; "" when a descriptor path is on
// the way.
std::string link_target(const std::string& path) {
  fs::path p = path;
  for (int hops = 0; hops < 40; ++hops) {
    if (is_descriptor_path(p)) return "";
    std::error_code ec;
    if (!fs::is_symlink(fs::symlink_status(p, ec))) return p.string();
    const fs::path next = fs::read_symlink(p, ec);
    if (ec) return p.string();
    p = next.is_absolute() ? next : p.parent_path() / next;
  }
  throw std::runtime_error("cannot write " + path + ": too many levels of symbolic links");
}

// The descriptor number of /dev/stdout, /dev/stderr, /dev/fd/N, /proc/self/fd/N; -1 otherwise.
int own_descriptor(const std::string& path) {
  if (path == "/dev/stdout") return 1;
  if (path == "/dev/stderr") return 2;
  for (const std::string& prefix :
       {std::string("/dev/fd/"), std::string("/proc/self/fd/"), "/proc/" + std::to_string(::getpid()) + "/fd/"}) {
    if (path.rfind(prefix, 0) != 0) continue;
    const std::string n = path.substr(prefix.size());
    if (n.empty() || n.size() > 9 || n.find_first_not_of("0123456789") != std::string::npos) return -1;
    return std::stoi(n);
  }
  return -1;
}

// Devices, FIFOs, sockets and the process's own descriptors (/dev/stdout, /proc/self/fd/N) are
// written into as they are: replacing them by a regular file would destroy them. The process's own
// descriptors are written to directly, so what preceded and what follows on them (through a shell's
// `> file` too) stays in order; anything else is opened for appending.
void write_through(const std::string& path, const std::function<void(const ChunkWriter&)>& produce) {
  const int own = own_descriptor(path);
  const int fd = own >= 0 ? own : ::open(path.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
  if (fd < 0) throw std::runtime_error("cannot write " + path + ": " + os_error());
  std::string error;
  try {
    error = stream_into(fd, produce);
  } catch (...) {
    if (own < 0) ::close(fd);
    throw;
  }
  if (own < 0 && ::close(fd) != 0 && error.empty()) error = os_error();
  if (!error.empty()) throw std::runtime_error("cannot write " + path + ": " + error);
}

}  // namespace

void write_file_durable(const std::string& requested, const std::function<void(const ChunkWriter&)>& produce) {
  struct stat st {};
  if (::stat(requested.c_str(), &st) == 0) {
    if (S_ISDIR(st.st_mode)) throw std::runtime_error("cannot write " + requested + ": it is a folder");
    if (!S_ISREG(st.st_mode)) return write_through(requested, produce);
  }
  // A regular file, or none yet: a symbolic link is followed, so the file it names is replaced
  // and the link stays a link.
  const std::string path = link_target(requested);
  if (path.empty()) return write_through(requested, produce);
  const std::string tmp = path + ".tmp." + std::to_string(::getpid());
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error("cannot write " + path + ": " + os_error() + " (opening " + tmp + ")");
  std::string error;
  try {
    error = stream_into(fd, produce);
  } catch (...) {
    ::close(fd);
    ::unlink(tmp.c_str());
    throw;
  }
  const std::string folder = fs::path(path).parent_path().string();
  const bool deferred = defer_sync(folder);
  if (error.empty() && !deferred && ::fsync(fd) != 0) error = os_error();
  if (::close(fd) != 0 && error.empty()) error = os_error();
  if (error.empty() && ::rename(tmp.c_str(), path.c_str()) != 0) error = os_error() + " (renaming " + tmp + ")";
  if (!error.empty()) {
    ::unlink(tmp.c_str());
    throw std::runtime_error("cannot write " + path + ": " + error + "; the file that stood there is unchanged");
  }
  if (!deferred) sync_dir(folder);
}

namespace {
// The folders written into since the last flush, taken for flushing.
std::set<std::string> take_deferred_folders() {
  std::lock_guard<std::mutex> lock(g_deferred_mutex);
  return std::exchange(g_deferred_folders, {});
}
}  // namespace

DeferredSync::DeferredSync() {
  std::lock_guard<std::mutex> lock(g_deferred_mutex);
  ++g_deferred;
}

void DeferredSync::commit() {
  const auto error = flush_file_systems(take_deferred_folders());
  if (!error.empty()) throw std::runtime_error("cannot flush the files written to disk: " + error);
}

DeferredSync::~DeferredSync() {
  bool last = false;
  {
    std::lock_guard<std::mutex> lock(g_deferred_mutex);
    last = --g_deferred == 0;
  }
  if (last) flush_file_systems(take_deferred_folders());  // (a destructor throws nothing: commit() reports errors)
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

std::string unreadable_file_reason(const std::string& path) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  switch (status.type()) {
    case std::filesystem::file_type::regular:
      return "";
    case std::filesystem::file_type::directory:
      return "is a folder, not a file";
    case std::filesystem::file_type::fifo:
      return "is a FIFO (named pipe), not a file";
    case std::filesystem::file_type::character:
    case std::filesystem::file_type::block:
      return "is a device, not a file";
    case std::filesystem::file_type::socket:
      return "is a socket, not a file";
    case std::filesystem::file_type::not_found:
      return "no such file";
    default:
      return ec ? "cannot be read (" + ec.message() + ")" : "is not a regular file";
  }
}

std::string zero_padded(long long number, int digits) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%0*lld", digits, number);
  return buf;
}

namespace {

bool is_zip_archive(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  char magic[4] = {};
  return f.read(magic, 4) && magic[0] == 'P' && magic[1] == 'K' && magic[2] == 3 && magic[3] == 4;
}

}  // namespace

void check_outputs(const std::vector<NamedPath>& outputs, const std::vector<std::string>& inputs, bool force) {
  namespace fs = std::filesystem;
  std::error_code ec;
  for (size_t i = 0; i < outputs.size(); ++i) {
    const auto& [option, path] = outputs[i];
    if (path.empty()) continue;
    const auto where = fs::weakly_canonical(path, ec);
    for (size_t j = 0; j < i; ++j)
      if (!outputs[j].path.empty() && fs::weakly_canonical(outputs[j].path, ec) == where)
        throw std::runtime_error(outputs[j].option + " and " + option + " name one file '" + path +
                                 "': one of them would be lost");
    if (!fs::exists(path, ec)) continue;
    for (const auto& in : inputs) {
      if (in.empty() || !fs::exists(in, ec)) continue;
      if (fs::equivalent(path, in, ec))
        throw std::runtime_error(option + " '" + path + "' is '" + in +
                                 "', which this command reads: refusing to replace it");
      if (fs::is_directory(in, ec)) {
        const auto dir = fs::weakly_canonical(in, ec);
        const auto rel = where.lexically_relative(dir);
        if (!rel.empty() && *rel.begin() != "..")
          throw std::runtime_error(option + " '" + path + "' is a file inside '" + in +
                                   "', which this command reads: refusing to replace it");
      }
    }
    if (!force && fs::is_regular_file(path, ec) && is_zip_archive(path))
      throw std::runtime_error(option + " '" + path +
                               "' is a model or checkpoint (a zip archive): refusing to replace it");
  }
}

namespace {
thread_local std::string* remove_tree_error = nullptr;
int remove_entry(const char* path, const struct stat*, int, struct FTW*) {
  if (::remove(path) == 0 || errno == ENOENT) return 0;
  if (remove_tree_error) *remove_tree_error = std::string(path) + ": " + std::strerror(errno);
  return 1;
}
}  // namespace

bool remove_tree(const std::string& path, std::string* error) {
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0 && errno == ENOENT) return true;
  std::string why;
  remove_tree_error = &why;
  // Children before their folder (FTW_DEPTH), links not followed (FTW_PHYS), 16 descriptors at most.
  const int rc = ::nftw(path.c_str(), remove_entry, 16, FTW_DEPTH | FTW_PHYS);
  remove_tree_error = nullptr;
  if (rc == 0) return true;
  if (error) *error = why.empty() ? path + ": " + std::strerror(errno) : why;
  return false;
}

}  // namespace geo
