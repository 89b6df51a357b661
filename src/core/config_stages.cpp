// The stages: section's names and checks.
#include "core/config_stages.h"

#include "core/config_check.h"

namespace geo {

const std::vector<EnumName<Net>>& enum_names(Net) {
  static const std::vector<EnumName<Net>> n{{Net::kDepth, "depth"}, {Net::kPose, "pose"}, {Net::kFlow, "flow"}};
  return n;
}

const std::vector<EnumName<LrScheduleKind>>& enum_names(LrScheduleKind) {
  static const std::vector<EnumName<LrScheduleKind>> n{{LrScheduleKind::kConstant, "constant"},
                                                       {LrScheduleKind::kStep, "step"}};
  return n;
}

std::vector<std::string> NetworkSet::names() const {
  std::vector<std::string> out;
  for (const auto& n : enum_names(Net{}))
    if (has(n.value)) out.emplace_back(n.name);
  return out;
}

void LossWeights::validate(Checker& c) const {
  c.require(rigid >= 0, "rigid", rigid, "must be >= 0");
  c.require(flow >= 0, "flow", flow, "must be >= 0");
  c.require(disp_smooth >= 0, "disp_smooth", disp_smooth, "must be >= 0");
  c.require(flow_smooth >= 0, "flow_smooth", flow_smooth, "must be >= 0");
  c.require(flow_consistency >= 0, "flow_consistency", flow_consistency, "must be >= 0");
  c.require(ground >= 0, "ground", ground, "must be >= 0");
  c.require(anchor >= 0, "anchor", anchor, "must be >= 0");
}

void StageConfig::validate(Checker& c) const {
  // Stage names become file names (checkpoints/<name>-<iteration>.pt, summaries/<name>-...).
  const bool plain =
      !name.empty() && name != "." && name != ".." &&
      name.find_first_not_of("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_.-") == std::string::npos;
  c.require(plain, "name", name, "must be a plain name of letters, digits, '_', '-' and '.' (it names files)");
  // best-<name>.pt must not read as a checkpoint <stage>-NNNNNNNN.pt.
  const bool numbered = name.size() >= 9 && name[name.size() - 9] == '-' &&
                        name.find_first_not_of("0123456789", name.size() - 8) == std::string::npos;
  c.require(!numbered, "name", name, "must not end in '-' and eight digits (the checkpoints' numbering)");
  c.require(iterations > 0 && iterations <= kMaxCount, "iterations", iterations, kCountRange);
  c.require(!train.empty(), "train", train.names(), "must name at least one of depth, pose, flow");
  c.require(learning_rate > 0 && learning_rate <= 1, "learning_rate", learning_rate,
            "must be in (0, 1] (GeoNet: 0.0002)");
  c.require(batch_size >= 1 && batch_size <= 65536, "batch_size", batch_size, "must be in 1..65536");
  c.require(lr_schedule != LrScheduleKind::kStep || lr_step > 0, "lr_step", lr_step,
            "must be > 0 when lr_schedule is step");
  c.require(lr_step >= 0 && lr_step <= kMaxCount, "lr_step", lr_step, "must be in 0..1000000000000");
  c.require(lr_gamma > 0 && lr_gamma <= 1, "lr_gamma", lr_gamma, "must be in (0, 1]");
  if (uses_flow())
    c.require(weights.flow > 0 || weights.flow_smooth > 0 || weights.flow_consistency > 0, "train", train.names(),
              "trains flow, so at least one flow loss weight must be > 0");
  c.require(weights.anchor == 0 || train.depth, "train", train.names(),
            "must include depth when weights.anchor is > 0 (the anchor holds the trained depth)");
  c.require(hold_masked >= 0 && hold_masked <= 1, "hold_masked", hold_masked,
            "must be in [0, 1] (the share of auto-masked pixels at which depth is held; 0: never)");
  c.section("weights", weights);
}

StageConfig StageConfig::held_depth() const {
  StageConfig s = *this;
  if (!train.pose && !train.flow) return s;
  s.train.depth = false;
  s.weights.anchor = 0;
  return s;
}

}  // namespace geo
