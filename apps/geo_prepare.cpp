// geo_prepare: packs a training split into a cache the trainer reads without OpenCV and without
// decoding PNGs (data/packed.h), and measures the loader's throughput.
//   geo_prepare --config stage1.yaml --set data.root=/data/kitti_raw --out /data/kitti_packed
//   geo_train --config stage1.yaml --set data.root=/data/kitti_packed
//   geo_prepare --config stage1.yaml --set data.root=... --throughput [--batches 20]
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>

#include <filesystem>

#include "core/config.h"
#include "core/logging.h"
#include "core/progress.h"
#include "core/runtime.h"
#include "data/loader.h"
#include "data/packed.h"
#include "data/training_data.h"
#include "app_options.h"

int main(int argc, char** argv) {
  CLI::App app{"geo_prepare: pack a KITTI/synthetic training split into a fast cache; measure loader throughput"};
  std::string config_path = "stage1.yaml", out;
  std::vector<std::string> overrides;
  bool throughput = false;
  int batches = 20, batch_size = 0;
  geo::app::add_config_options(app, config_path, overrides, "config whose data section is used (default stage1.yaml)");
  app.add_option("--out", out, "cache folder to write (train/ and val/ inside)");
  app.add_flag("--throughput", throughput, "measure samples/s of the configured data instead of packing");
  app.add_option("--batches", batches, "batches to time with --throughput")->check(geo::app::positive());
  app.add_option("--batch-size", batch_size, "batch size for --throughput (default: the first stage's)")->check(geo::app::positive());
  CLI11_PARSE(app, argc, argv);
  return geo::app::run_tool([&] {
    const auto cfg = geo::load_config(geo::resolve_config_path(config_path), overrides);
    auto data = geo::open_training_data(cfg.data);
    spdlog::info("{} data: {} training snippets ({} excluded, {} without neighbours), {} validation",
                 data.format, data.train->size(), data.excluded, data.dropped, data.val ? data.val->size() : 0);
    if (throughput) {
      const auto lo = geo::loader_options(cfg.data, batch_size > 0 ? batch_size : cfg.stages.front().batch_size);
      spdlog::info("loader: {:.1f} samples/s ({} batches of {}, {}x{}, {} worker(s), augmentation {})",
                   geo::measure_throughput(data.train, lo, batches), batches, lo.batch_size, cfg.data.width, cfg.data.height,
                   lo.workers, cfg.data.augment.enabled ? "on" : "off");
      return 0;
    }
    if (out.empty()) throw std::runtime_error("give --out DIR (or --throughput)");
    // One identifier for train/ and val/: the trainer refuses a val/ left by another run.
    const std::string pack_id = geo::new_pack_id();
    auto pack = [&](const std::shared_ptr<geo::SnippetSource>& src, const std::string& dir) {
      geo::PackedWriter w(dir, cfg.data.height, cfg.data.width, cfg.data.seq_length, pack_id);
      geo::Progress progress(dir, static_cast<int64_t>(src->size()), 500, "snippets");
      for (size_t i = 0; i < src->size(); ++i) {
        w.add(src->get(i));
        progress.update(static_cast<int64_t>(i + 1));
      }
      w.finish();
    };
    pack(data.train, out + "/train");
    if (data.val) {
      pack(data.val, out + "/val");
    } else if (geo::has_packed_cache_files(out + "/val")) {  // an earlier run's: no longer this cache's
      geo::remove_packed_cache_files(out + "/val");
      spdlog::info("removed {}/val: an earlier geo_prepare's validation set (this config has none)", out);
    }
    spdlog::info("cache written: train with --set data.root={}", out);
    return 0;
  });
}
