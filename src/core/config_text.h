// How config values are written in YAML and in error messages, shared by the parts of core/config
// (config.cpp: parsing, emitting, overrides; config_check.h: validation). Internal.
#pragma once

#include "core/config_base.h"

#include <cmath>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

namespace geo::config_text {

inline std::string join(const std::string& prefix, const std::string& key) {
  return prefix.empty() ? key : prefix + "." + key;
}

// Formats a double with the fewest digits that read back to the same value; plain decimals (700,
// 0.0002) where up to 6 decimals do, never 7e+02.
inline std::string format_double(double v) {
  if (std::isfinite(v) && std::fabs(v) < 1e15 && (v == 0 || std::fabs(v) >= 1e-4)) {
    for (int decimals = 0; decimals <= 6; ++decimals) {
      std::ostringstream os;
      os.setf(std::ios::fixed);
      os.precision(decimals);
      os << v;
      if (std::stod(os.str()) == v) return os.str();
    }
  }
  for (int precision = 1; precision <= 17; ++precision) {
    std::ostringstream os;
    os.precision(precision);
    os << v;
    if (std::stod(os.str()) == v) return os.str();
  }
  std::ostringstream os;
  os.precision(17);
  os << v;
  return os.str();
}

template <class T>
std::string to_text(const T& v) {
  if constexpr (std::is_enum_v<T>) {
    return std::string("'") + name_of(v) + "'";
  } else {
    std::ostringstream os;
    os << v;
    return os.str();
  }
}
inline std::string to_text(double v) { return format_double(v); }
inline std::string to_text(bool v) { return v ? "true" : "false"; }
inline std::string to_text(const std::string& v) { return "'" + v + "'"; }
inline std::string to_text(const std::vector<std::string>& v) {
  std::string s = "[";
  for (size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + v[i];
  return s + "]";
}
inline std::string to_text(const std::vector<double>& v) {
  std::string s = "[";
  for (size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + format_double(v[i]);
  return s + "]";
}

template <class E>
std::string valid_names() {
  std::string all;
  for (const auto& n : enum_names(E{})) all += (all.empty() ? "" : ", ") + std::string(n.name);
  return all;
}

}  // namespace geo::config_text
