// The loss: section's names and checks.
#include "core/config_loss.h"

#include "core/config_check.h"

namespace geo {

const std::vector<EnumName<Sampler>>& enum_names(Sampler) {
  static const std::vector<EnumName<Sampler>> n{{Sampler::kZeros, "zeros"}, {Sampler::kBorder, "border"}};
  return n;
}

const std::vector<EnumName<FlowMask>>& enum_names(FlowMask) {
  static const std::vector<EnumName<FlowMask>> n{{FlowMask::kOcclusion, "occlusion"},
                                                 {FlowMask::kConsistency, "consistency"}};
  return n;
}

const std::vector<EnumName<FlowReduction>>& enum_names(FlowReduction) {
  static const std::vector<EnumName<FlowReduction>> n{{FlowReduction::kPerSource, "per_source"},
                                                      {FlowReduction::kGeoNet, "geonet"}};
  return n;
}

void LossConfig::validate(Checker& c) const {
  c.require(ssim_alpha >= 0 && ssim_alpha <= 1, "ssim_alpha", ssim_alpha, "must be in [0, 1]");
  c.require(occ_alpha1 >= 0, "occ_alpha1", occ_alpha1, "must be >= 0");
  c.require(occ_alpha2 >= 0, "occ_alpha2", occ_alpha2, "must be >= 0");
  c.require(consistency_a >= 0, "consistency_a", consistency_a, "must be >= 0");
  c.require(consistency_b >= 0, "consistency_b", consistency_b, "must be >= 0");
  const bool range_ok = image_range.size() == 2 && ((image_range[0] == -1.0 && image_range[1] == 1.0) ||
                                                    (image_range[0] == 0.0 && image_range[1] == 1.0));
  c.require(range_ok, "image_range", image_range, "must be [-1, 1] (GeoNet) or [0, 1]");
}

}  // namespace geo
