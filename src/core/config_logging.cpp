// The logging: section's checks.
#include "core/config_logging.h"

#include "core/config_check.h"

namespace geo {

void LoggingConfig::validate(Checker& c) const {
  c.require(one_of(level, {"trace", "debug", "info", "warn", "error"}), "level", level,
            "must be trace, debug, info, warn or error");
  c.require(interval > 0 && interval <= kMaxCount, "interval", interval, kCountRange);
  c.require(summary_interval >= 0 && summary_interval <= kMaxCount, "summary_interval", summary_interval,
            "must be in 0..1000000000000 (0 = off)");
  c.require(checkpoint_interval > 0 && checkpoint_interval <= kMaxCount, "checkpoint_interval", checkpoint_interval,
            kCountRange);
  c.require(val_interval >= 0 && val_interval <= kMaxCount, "val_interval", val_interval,
            "must be in 0..1000000000000 (0 = off)");
  c.require(keep_last >= 1 && keep_last <= 1000000, "keep_last", keep_last, "must be in 1..1000000");
  c.require(max_bad_steps >= 1 && max_bad_steps <= 1000000, "max_bad_steps", max_bad_steps, "must be in 1..1000000");
}

}  // namespace geo
