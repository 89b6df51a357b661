// What the command-line tools share: one frame for running a tool (process settings, logging, errors
// as messages and exit codes) and range checks whose messages say what is expected.
#pragma once

#include <CLI/CLI.hpp>

#include "core/config.h"
#include "core/logging.h"
#include "core/runtime.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdlib>
#include <cstdint>
#include <string>
#include <vector>

namespace geo::app {

// Runs a tool's work once its options are parsed: every core for LibTorch (a tool's --threads or
// run.threads may set fewer), logging at info, and any exception as one error line naming what is
// wrong with exit code 1 (a tool's own codes, e.g. 130 for an interrupted training, come back from
// `body`).
template <class Body>
int run_tool(Body&& body) {
  use_all_cores();
  try {
    setup_logging("info");
    return body();
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
}

// An option given an empty value (--output '', a variable that was not set): named, rather than
// taken as the current folder, no file or a default.
inline void refuse_empty_values(const CLI::App& app) {
  for (const CLI::Option* opt : app.get_options())
    if (opt->count() > 0 && opt->get_expected_min() > 0)
      for (const auto& value : opt->results())
        if (value.empty())
          throw std::runtime_error(opt->get_name() + " '': an empty value (" +
                                   (opt->get_type_name() == "TEXT" || opt->get_type_name().empty()
                                        ? std::string("a path or name")
                                        : "a " + opt->get_type_name()) +
                                   " was expected)");
}

// A whole tool: its command line described by `add(app, command)` into a `Command`, parsed (--help
// and parse errors as CLI11 reports them), then `run(command)` inside run_tool.
template <class Command, class Add, class Run>
int run_command(int argc, char** argv, const std::string& description, Add&& add, Run&& run) {
  CLI::App app{description};
  Command command;
  add(app, command);
  CLI11_PARSE(app, argc, argv);
  return run_tool([&] {
    refuse_empty_values(app);
    return run(command);
  });
}

// A number >= `min` (or > `min` when `strict`), integers and reals alike: "must be >= 1 (got 0)"
// rather than CLI11's "Value 0 not in range 0.000000 to 1.797e308".
inline CLI::Validator bounded_below(long long min, bool strict) {
  const std::string bound = (strict ? "> " : ">= ") + std::to_string(min);
  return CLI::Validator(
      [min, strict, bound](std::string& value) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(value.c_str(), &end);
        if (value.empty() || end != value.c_str() + value.size() || !std::isfinite(v))
          return "must be a number " + bound + " (got '" + value + "')";
        if (strict ? !(v > static_cast<double>(min)) : v < static_cast<double>(min))
          return "must be " + bound + " (got " + value + ")";
        return "";
      },
      bound);
}

inline CLI::Validator positive() { return bounded_below(1, false); }      // counts: 1, 2, ...
inline CLI::Validator non_negative() { return bounded_below(0, false); }  // 0 = off / all
inline CLI::Validator above_zero() { return bounded_below(0, true); }     // lengths, heights

// --config FILE (a path or a shipped config's name, e.g. stage1.yaml) and --set KEY=VALUE...
// (config overrides). Returns the --config option.
inline CLI::Option* add_config_options(CLI::App& app, std::string& config, std::vector<std::string>& overrides,
                                       const std::string& config_help) {
  auto* option = app.add_option("--config", config, config_help);
  app.add_option("--set", overrides, "override a config key, e.g. --set data.root=/data/kitti_raw")->take_all();
  return option;
}

// --device auto|cpu|cuda|cuda:N, checked when parsed; `unset` says what leaving it out means.
inline CLI::Option* add_device_option(CLI::App& app, std::string& device, const std::string& unset) {
  return app
      .add_option("--device", device,
                  "auto (CUDA when available), cpu, cuda or cuda:N (an error without CUDA); " + unset)
      ->check(CLI::Validator(
          [](std::string& value) -> std::string {
            return is_device_name(value) ? "" : std::string(kDeviceNameRule) + " (got '" + value + "')";
          },
          "DEVICE"));
}

// --precision, one of `choices`.
inline CLI::Option* add_precision_option(CLI::App& app, std::string& precision, const std::vector<std::string>& choices,
                                         const std::string& help) {
  return app.add_option("--precision", precision, help)->check(CLI::IsMember(choices));
}

// --calibration FRAMES and --calibration-frames N (1..1000) of a tool that calibrates int8 on the
// first frames of a folder or video; `with` names the option they serve ("--int8", "--precision int8").
inline void add_calibration_options(CLI::App& app, std::string& frames, int64_t& count, const std::string& with) {
  app.add_option("--calibration", frames,
                 "with " + with +
                     ": a folder of frames or a video like those the model will see (its first frames "
                     "calibrate it)");
  app.add_option("--calibration-frames", count, "with " + with + ": how many frames calibrate it, 1..1000")
      ->check(CLI::Range(1, 1000));
}

}  // namespace geo::app
