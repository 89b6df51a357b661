// Logging setup (spdlog).
#pragma once

#include <string>

namespace geo {

// Configures the default spdlog logger once: console, optional log file, level by name
// (trace|debug|info|warn|error). Unknown level -> std::invalid_argument naming it.
void setup_logging(const std::string& level, const std::string& log_file = "");

}  // namespace geo
