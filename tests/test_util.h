// Helpers shared by the test suites: fresh temporary folders and the optional KITTI excerpts.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <system_error>
#include <vector>
#include <unistd.h>

#include "core/files.h"

namespace geo::test {

// Folders made by fresh_dir in this process, removed when it exits (checkpoints of the trainer
// tests take gigabytes); GEO_KEEP_TEST_DIRS=1 keeps them for inspection.
inline std::vector<std::string>& made_dirs() {
  static std::vector<std::string> dirs;
  return dirs;
}
inline void remove_made_dirs() {
  const char* keep = std::getenv("GEO_KEEP_TEST_DIRS");
  if (keep && std::string(keep) == "1") return;
  for (const auto& d : made_dirs()) {
    geo::remove_tree(d);
  }
}

// A new empty folder under the system temp dir, unique per process and name.
inline std::string fresh_dir(const std::string& name) {
  const auto dir = std::filesystem::temp_directory_path() / ("geo_test_" + name + "_" + std::to_string(::getpid()));
  std::string error;
  if (!geo::remove_tree(dir.string(), &error)) throw std::runtime_error("fresh_dir: " + error);
  std::filesystem::create_directories(dir);
  if (made_dirs().empty()) std::atexit(remove_made_dirs);
  made_dirs().push_back(dir.string());
  return dir.string();
}

inline void write_text(const std::string& path, const std::string& text) {
  std::filesystem::create_directories(std::filesystem::path(path).parent_path());
  std::ofstream(path, std::ios::binary) << text;
}

inline std::string read_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

#ifndef GEO_TEST_SHARED_DIR
#define GEO_TEST_SHARED_DIR "../shared"
#endif
#ifndef GEO_TEST_APPS_DIR
#define GEO_TEST_APPS_DIR "apps"
#endif

// ../shared/kitti_samples (GEO_SHARED_DIR, else the folder beside the source tree), or "" when absent.
inline std::string kitti_samples() {
  const char* env = std::getenv("GEO_SHARED_DIR");
  const std::string dir = std::string(env ? env : GEO_TEST_SHARED_DIR) + "/kitti_samples";
  return std::filesystem::exists(dir + "/README.md") ? dir : "";
}

// A NumPy .npy file (format 1.0) with the header dict `header` as written, padded as NumPy pads it,
// followed by `data`.
inline std::string npy_bytes(std::string header, const std::string& data) {
  header += std::string(63 - (10 + header.size()) % 64, ' ') + "\n";
  std::string out = std::string("\x93NUMPY\x01\x00", 8);
  out += static_cast<char>(header.size() & 0xff);
  out += static_cast<char>(header.size() >> 8);
  return out + header + data;
}

// The built tools (geo_train, ...): GEO_APPS_DIR, else the build tree's apps/.
inline std::string apps_dir() {
  const char* env = std::getenv("GEO_APPS_DIR");
  return env ? env : GEO_TEST_APPS_DIR;
}

}  // namespace geo::test

// Message check for EXPECT_THROW-style tests: runs `stmt`, expects a std::exception whose what()
// contains every given fragment.
#define GEO_EXPECT_THROW_WITH(stmt, ...)                                                                            \
  do {                                                                                                              \
    bool geo_thrown = false;                                                                                        \
    try {                                                                                                           \
      stmt;                                                                                                         \
    } catch (const std::exception& geo_e) {                                                                         \
      geo_thrown = true;                                                                                            \
      const std::string geo_msg = geo_e.what();                                                                     \
      for (const std::string& geo_f : std::initializer_list<std::string>{__VA_ARGS__})                              \
        EXPECT_NE(geo_msg.find(geo_f), std::string::npos) << "message '" << geo_msg << "' lacks '" << geo_f << "'"; \
    }                                                                                                               \
    EXPECT_TRUE(geo_thrown) << #stmt " did not throw";                                                              \
  } while (0)
