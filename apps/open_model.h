// How the tools that predict open a model (geo_infer, geo_export): on huge pages while it loads
// (core/runtime.h: HugePages).
#pragma once

#include "core/runtime.h"
#include "geo/geo.h"

#include <string>

namespace geo::app {

inline Model open_model(const std::string& path, const LoadOptions& options = {}) {
  const HugePages while_opening;
  return Model::load(path, options);
}

}  // namespace geo::app
