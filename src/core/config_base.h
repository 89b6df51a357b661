// What every section of a config (core/config_<section>.h) is built of: the error, enumerated keys
// by name, and the checker each section's validate() reports to (core/config_check.h).
#pragma once

#include <stdexcept>
#include <string>
#include <vector>

namespace geo {

// Thrown for every configuration problem; the message names the file, key, value and line.
class ConfigError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class Checker;  // collects validation failures with key paths and YAML lines (core/config_check.h)

// Enumerated keys: read from YAML by name once, at parsing (an unknown name is a ConfigError listing
// the valid ones), written back by name, compared as values everywhere else. Each enumeration's
// section declares enum_names(E) listing its names.
template <class E>
struct EnumName {
  E value;
  const char* name;
};

// The YAML name of an enumerated value ("nearest").
template <class E>
const char* name_of(E value) {
  for (const auto& n : enum_names(E{}))
    if (n.value == value) return n.name;
  return "?";
}

}  // namespace geo
