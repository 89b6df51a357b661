// The model: section's names and checks.
#include "core/config_model.h"

#include "core/config_check.h"

namespace geo {

const std::vector<EnumName<Upsample>>& enum_names(Upsample) {
  static const std::vector<EnumName<Upsample>> n{{Upsample::kNearest, "nearest"}, {Upsample::kBilinear, "bilinear"}};
  return n;
}

void ModelConfig::validate(Checker& c) const {
  c.require(encoder_depth == 18 || encoder_depth == 34 || encoder_depth == 50, "encoder_depth", encoder_depth,
            "must be 18, 34 or 50");
  c.require(fr_ratio >= 1 && fr_ratio <= 4096, "fr_ratio", fr_ratio, "must be in 1..4096");
  c.require(num_scales >= 1 && num_scales <= 4, "num_scales", num_scales, "must be in 1..4");
  c.require(bn_eps > 0, "bn_eps", bn_eps, "must be > 0");
  c.require(bn_momentum > 0 && bn_momentum <= 1, "bn_momentum", bn_momentum, "must be in (0, 1]");
}

}  // namespace geo
