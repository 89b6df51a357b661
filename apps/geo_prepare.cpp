// geo_prepare: packs a training split into a cache the trainer reads without OpenCV and without
// decoding PNGs (data/packed/packed.h), and measures the loader's throughput.
//   geo_prepare --config stage1.yaml --set data.root=/data/kitti_raw --out /data/kitti_packed
//   geo_train --config stage1.yaml --set data.root=/data/kitti_packed
//   geo_prepare --config stage1.yaml --set data.root=... --throughput [--batches 20]
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include <filesystem>

#include "core/config.h"
#include "core/files.h"
#include "data/loader.h"
#include "data/training_data.h"
#include "app_options.h"

namespace {

struct PrepareCommand {
  std::string config = "stage1.yaml", out;
  std::vector<std::string> overrides;
  bool throughput = false;
  int batches = 20, batch_size = 0;
};

void add_options(CLI::App& app, PrepareCommand& c) {
  geo::app::add_config_options(app, c.config, c.overrides, "config whose data section is used (default stage1.yaml)");
  app.add_option("--out", c.out, "cache folder to write (train/ and val/ inside)");
  app.add_flag("--throughput", c.throughput, "measure samples/s of the configured data instead of packing");
  app.add_option("--batches", c.batches, "batches to time with --throughput")->check(geo::app::positive());
  app.add_option("--batch-size", c.batch_size, "batch size for --throughput (default: the first stage's)")
      ->check(geo::app::positive());
}

int prepare(const PrepareCommand& c) {
  const auto cfg = geo::load_config(geo::resolve_config_path(c.config), c.overrides);
  if (!c.throughput && c.out.empty()) throw std::runtime_error("give --out DIR (or --throughput)");
  // The cache is never written over what the config reads (a packed data.root among them).
  if (!c.throughput) geo::check_outputs({{"--out", c.out}}, geo::config_reads(cfg), true);
  const auto data = geo::open_training_data(cfg.data);
  spdlog::info("{} data: {} training snippets ({} excluded, {} without neighbours), {} validation", data.format,
               data.train->size(), data.excluded, data.dropped, data.val ? data.val->size() : 0);
  if (c.throughput) {
    const auto lo = geo::loader_options(cfg.data, c.batch_size > 0 ? c.batch_size : cfg.stages.front().batch_size);
    spdlog::info("loader: {:.1f} samples/s ({} batches of {}, {}x{}, {} worker(s), augmentation {})",
                 geo::measure_throughput(data.train, lo, c.batches), c.batches, lo.batch_size, cfg.data.width,
                 cfg.data.height, lo.workers, cfg.data.augment.enabled ? "on" : "off");
    return 0;
  }
  if (geo::write_packed_cache(data, cfg.data, c.out))
    spdlog::info("removed {}/val: an earlier geo_prepare's validation set (this config has none)", c.out);
  spdlog::info("cache written: train with --set data.root={}", c.out);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return geo::app::run_command<PrepareCommand>(
      argc, argv, "geo_prepare: pack a KITTI/synthetic training split into a fast cache; measure loader throughput",
      add_options, prepare);
}
