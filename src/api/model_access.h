// What geo's own tools need of a geo::Model beyond the public API (include/geo/geo.h): the config
// the networks were built from, and an untrained model of a config (geo_eval's "before training"
// baseline). Not installed.
#pragma once

#include "core/config.h"
#include "geo/geo.h"

namespace geo {

struct ModelAccess {
  static const Config& config(const Model& model);
  // Networks of `config` with LibTorch's initialisation (seed the generator first for a fixed one).
  // `precision` as LoadOptions::precision (geo_bench times the library path in both).
  static Model untrained(const Config& config, const std::string& device, const std::string& precision = "fp32");
};

}  // namespace geo
