// What geo's code logs while `body` runs, as lines of `pattern` (spdlog's default logger swapped for
// one writing into a string, progress lines in the non-terminal form: GEO_PROGRESS=lines).
#pragma once

#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <cstdlib>
#include <sstream>
#include <string>

namespace geo::test {

template <class F>
std::string captured_log(const std::string& pattern, F&& body) {
  setenv("GEO_PROGRESS", "lines", 1);
  std::ostringstream out;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(out);
  sink->set_pattern(pattern);
  auto saved = spdlog::default_logger();
  spdlog::set_default_logger(std::make_shared<spdlog::logger>("captured", sink));
  try {
    body();
  } catch (...) {
    spdlog::set_default_logger(saved);
    unsetenv("GEO_PROGRESS");
    throw;
  }
  spdlog::set_default_logger(saved);
  unsetenv("GEO_PROGRESS");
  return out.str();
}

}  // namespace geo::test
