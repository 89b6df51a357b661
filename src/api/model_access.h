// What geo's own tools need of a geo::Model beyond the public API (include/geo/geo.h): an untrained
// model of a spec (geo_eval's "before training" baseline, geo_bench's library row). Not installed.
#pragma once

#include "geo/geo.h"
#include "pipeline/networks.h"

#include <optional>
#include <string>
#include <vector>

namespace geo {

struct ModelAccess {
  // Networks of `spec` with LibTorch's initialisation (seed the generator first for a fixed one);
  // `name` becomes ModelSpec::source. `precision` as LoadOptions::precision.
  static Model untrained(const NetworkSpec& spec, const std::string& name, const std::string& device,
                         const std::string& precision = "fp32");
  // The config a training checkpoint carries (nullopt for geo_export's model files and untrained models).
  static const std::optional<Config>& training_config(const Model& model);
  // The configs of the checkpoints its weights started from (CheckpointContents::init_configs).
  static const std::vector<std::string>& init_configs(const Model& model);
};

}  // namespace geo
