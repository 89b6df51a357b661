// Logging setup (spdlog) and the files every run writes.
#pragma once

#include <string>

namespace geo {

// Configures the default spdlog logger once: console, optional log file, level by name
// (trace|debug|info|warn|error). Unknown level -> std::invalid_argument naming it.
void setup_logging(const std::string& level, const std::string& log_file = "");

// Writes `content` to `path` through a temporary file renamed into place, so a crash never leaves
// a half-written file where a good one stood. Throws std::runtime_error naming the path.
void write_file_atomic(const std::string& path, const std::string& content);

// Creates <parent>/<name>-YYYYmmdd-HHMMSS (suffixing -2, -3... if taken) and returns it.
std::string make_run_dir(const std::string& parent, const std::string& name);

}  // namespace geo
