// Logging setup (spdlog).
#pragma once

#include <sstream>
#include <string>

namespace geo {

// Configures the default spdlog logger once: console, optional log file, level by name
// (trace|debug|info|warn|error). Unknown level -> std::invalid_argument naming it.
void setup_logging(const std::string& level, const std::string& log_file = "");

// "a, b, c" from any range of streamable values. geo's code does not use fmt::join or
// fmt::localtime: they moved between fmt 9 and 12 (LibTorch 2.x ships fmt 12), and geo builds on both.
template <class Range>
std::string join_list(const Range& items, const std::string& separator) {
  std::ostringstream s;
  bool first = true;
  for (const auto& x : items) {
    if (!first) s << separator;
    s << x;
    first = false;
  }
  return s.str();
}

// Today's local date, YYYY-MM-DD.
std::string local_date();

}  // namespace geo
