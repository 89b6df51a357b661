// Looking up an evaluation's figures by name in the tests (a missing name is a test failure).
#pragma once

#include "eval/protocols.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <string>

namespace geo::test {

inline double metric_of(const EvalResult& r, const std::string& name) {
  for (const auto& [key, value] : r.metrics)
    if (key == name) return value;
  ADD_FAILURE() << "no metric '" << name << "' in the result";
  return -1;
}

inline int64_t count_of(const EvalResult& r, const std::string& name) {
  for (const auto& [key, value] : r.counts)
    if (key == name) return value;
  ADD_FAILURE() << "no count '" << name << "' in the result";
  return -1;
}

}  // namespace geo::test
