// Typed configuration: YAML parsed once into nested structs, validated, never mutated afterwards.
//
// Each section is its own pair of files, core/config_<section>.h (its structs: keys, defaults,
// `fields(v)`) and .cpp (its enumerations' names and its checks): a new key is one edit there. Each
// struct lists its keys exactly once, in `fields(v)`: the same list drives parsing (unknown keys are
// errors naming the full key path), emitting the resolved config, and `--set key=value` overrides.
// Defaults are the paper's settings (GeoNet's where the paper is silent); the comment on each says
// where from. Parsing, emitting and overrides: config.cpp; files: config_files.cpp.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "core/config_base.h"
#include "core/config_data.h"
#include "core/config_logging.h"
#include "core/config_loss.h"
#include "core/config_model.h"
#include "core/config_optimizer.h"
#include "core/config_run.h"
#include "core/config_stages.h"

namespace geo {

struct Config {
  ModelConfig model;
  DataConfig data;
  LossConfig loss;
  std::vector<StageConfig> stages = {StageConfig{}};
  OptimizerConfig optimizer;
  LoggingConfig logging;
  RunConfig run;

  template <class V>
  void fields(V& v) {
    v("model", model);
    v("data", data);
    v("loss", loss);
    v("stages", stages);
    v("optimizer", optimizer);
    v("logging", logging);
    v("run", run);
  }

  // Throws ConfigError listing every problem found (key path, value, YAML line when known).
  void validate() const;

  // Where each key came from: "stages[0].learning_rate" -> 12 (1-based line), for messages.
  std::map<std::string, int> lines;
  std::string source;  // file the config was read from ("<string>" for text)
};

// Parses YAML text. `overrides` are "key.path=value" strings applied before typing (and so
// validated the same way). `source` names the text in messages.
Config parse_config(const std::string& yaml_text, const std::string& source = "<string>",
                    const std::vector<std::string>& overrides = {});

// Reads a YAML file (missing or unreadable file -> ConfigError naming the path).
Config load_config(const std::string& path, const std::vector<std::string>& overrides = {});

// Resolves a config argument: an existing path as given; otherwise a bare name (with or without
// .yaml) is looked up in the shipped configs/ folder. Throws naming every place it looked.
std::string resolve_config_path(const std::string& name);

// The shipped configs/ folder: GEO_CONFIG_DIR, else <prefix>/share/geo/configs beside an installed
// tool (cmake --install), else the source tree's configs/.
std::string shipped_config_dir();

// Every file and folder a config makes a command read: the config file itself, data.root, the
// training and validation lists, the clips, the camera's calibration file and each stage's init.
// What a command's outputs must not replace (core/files.h check_outputs).
std::vector<std::string> config_reads(const Config& config);

// The resolved config as YAML (every key, defaults included). parse_config(to_yaml(c)) == c.
std::string to_yaml(const Config& config);

// The keys whose values differ between two configs written by to_yaml, as "key: A vs B" lines
// (stages[1].batch_size: 4 vs 8), leaving out the keys in `ignore` (dotted paths, a section for all
// its keys).
std::vector<std::string> config_differences(const std::string& yaml_a, const std::string& yaml_b,
                                            const std::vector<std::string>& ignore = {});

}  // namespace geo
