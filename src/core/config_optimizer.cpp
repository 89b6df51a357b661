// The optimizer: section's checks.
#include "core/config_optimizer.h"

#include "core/config_check.h"

namespace geo {

void OptimizerConfig::validate(Checker& c) const {
  c.require(type == "adam", "type", type, "must be adam (the paper's optimiser)");
  c.require(beta1 >= 0 && beta1 < 1, "beta1", beta1, "must be in [0, 1)");
  c.require(beta2 >= 0 && beta2 < 1, "beta2", beta2, "must be in [0, 1)");
  c.require(eps > 0, "eps", eps, "must be > 0");
  c.require(weight_decay >= 0, "weight_decay", weight_decay, "must be >= 0");
  c.require(grad_clip >= 0, "grad_clip", grad_clip, "must be >= 0 (0 = off)");
}

}  // namespace geo
