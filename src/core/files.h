// Files every run writes: atomic replacement and run folders.
#pragma once

#include <string>

namespace geo {

// Writes `content` to `path` through a temporary file renamed into place, so a crash never leaves
// a half-written file where a good one stood. Throws std::runtime_error naming the path.
void write_file_atomic(const std::string& path, const std::string& content);

// Creates <parent>/<name>-YYYYmmdd-HHMMSS (suffixing -2, -3... if taken) and returns it.
std::string make_run_dir(const std::string& parent, const std::string& name);

}  // namespace geo
