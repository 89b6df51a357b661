// What the command-line tools share: range checks whose messages say what is expected.
#pragma once

#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdlib>
#include <string>

namespace geo::app {

// A number >= `min` (or > `min` when `strict`), integers and reals alike: "must be >= 1 (got 0)"
// rather than CLI11's "Value 0 not in range 0.000000 to 1.797e308".
inline CLI::Validator bounded_below(long long min, bool strict) {
  const std::string bound = (strict ? "> " : ">= ") + std::to_string(min);
  return CLI::Validator(
      [min, strict, bound](std::string& value) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(value.c_str(), &end);
        if (value.empty() || end != value.c_str() + value.size() || !std::isfinite(v))
          return "must be a number " + bound + " (got '" + value + "')";
        if (strict ? !(v > static_cast<double>(min)) : v < static_cast<double>(min))
          return "must be " + bound + " (got " + value + ")";
        return "";
      },
      bound);
}

inline CLI::Validator positive() { return bounded_below(1, false); }       // counts: 1, 2, ...
inline CLI::Validator non_negative() { return bounded_below(0, false); }   // 0 = off / all
inline CLI::Validator above_zero() { return bounded_below(0, true); }      // lengths, heights

}  // namespace geo::app
