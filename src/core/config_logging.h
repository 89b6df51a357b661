// The logging: section of a config (progress, summaries, checkpoints, validation).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "core/config_base.h"

namespace geo {

struct LoggingConfig {
  std::string level = "info";          // trace | debug | info | warn | error
  int64_t interval = 100;              // progress line every N iterations
  int64_t summary_interval = 5000;     // visual summaries every N iterations (0 = off)
  int64_t checkpoint_interval = 5000;  // checkpoint every N iterations (and at the end)
  int64_t val_interval = 5000;         // validation every N iterations (0 = off)
  int keep_last = 3;                   // checkpoints kept besides the best
  int max_bad_steps = 10;              // stop after this many NaN/Inf steps in a row

  template <class V>
  void fields(V& v) {
    v("level", level);
    v("interval", interval);
    v("summary_interval", summary_interval);
    v("checkpoint_interval", checkpoint_interval);
    v("val_interval", val_interval);
    v("keep_last", keep_last);
    v("max_bad_steps", max_bad_steps);
  }
  void validate(Checker& c) const;
};

}  // namespace geo
