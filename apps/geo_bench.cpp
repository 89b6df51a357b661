// geo_bench: parameter counts and inference timings of the paper's networks.
//   geo_bench --summary                      parameter counts, FR on and off
//   geo_bench [--config FILE] [--device cpu|cuda] [--batch N] [--json FILE]
// Timings: median of --iters runs after --warmup runs (>= 10 warm-ups by default: fresh memory is
// slow to touch on these machines), inference mode, BatchNorm in eval mode.
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <thread>

#include "core/config.h"
#include "core/logging.h"
#include "models/depth_net.h"
#include "models/flow_net.h"
#include "models/pose_net.h"

namespace {

struct Row {
  std::string name;
  std::string fr;
  int64_t params = 0;
  double ms = -1;  // < 0: not timed
};

template <class Fn> double median_ms(Fn&& fn, int warmup, int iters, const torch::Device& device) {
  auto sync = [&] {
    if (device.is_cuda()) torch::cuda::synchronize();
  };
  for (int i = 0; i < warmup; ++i) fn();
  sync();
  std::vector<double> times;
  for (int i = 0; i < iters; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    fn();
    sync();
    times.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(times.begin(), times.end());
  return times[times.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"geo_bench: parameter counts and inference timings of DepthNet, PoseNet and FlowNet"};
  std::string config_path, device_name = "cpu", json_path;
  bool summary = false;
  int batch = 1, warmup = 10, iters = 5, threads = 0;
  app.add_option("--config", config_path, "YAML config (model and data size); default: the paper's settings");
  app.add_option("--device", device_name, "cpu or cuda")->check(CLI::IsMember({"cpu", "cuda"}));
  app.add_option("--batch", batch, "batch size for the timings")->check(CLI::PositiveNumber);
  app.add_option("--warmup", warmup, "untimed runs before timing")->check(CLI::NonNegativeNumber);
  app.add_option("--iters", iters, "timed runs (the median is reported)")->check(CLI::PositiveNumber);
  app.add_option("--threads", threads, "intra-op threads (0 = all cores)")->check(CLI::NonNegativeNumber);
  app.add_option("--json", json_path, "also write the results as JSON to this file");
  app.add_flag("--summary", summary, "only print parameter counts (FR on and off), no timings");
  CLI11_PARSE(app, argc, argv);

  try {
    geo::setup_logging("info");
    const geo::Config config = config_path.empty()
                                   ? geo::parse_config("", "<defaults>")
                                   : geo::load_config(geo::resolve_config_path(config_path));
    if (device_name == "cuda" && !torch::cuda::is_available())
      throw std::runtime_error("--device cuda: CUDA is not available in this build/machine");
    const torch::Device device(device_name == "cuda" ? torch::kCUDA : torch::kCPU);
    const int nthreads = threads > 0 ? threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    torch::set_num_threads(nthreads);
    const int64_t H = config.data.height, W = config.data.width;
    spdlog::info("geo_bench: LibTorch {}, device {}, {} threads, input {}x{}, batch {}", TORCH_VERSION,
                 device.str(), nthreads, H, W, batch);

    std::vector<Row> rows;
    torch::manual_seed(0);
    for (bool fr : {true, false}) {
      geo::ModelConfig m = config.model;
      m.use_fr = fr;
      geo::DepthNet depth(geo::DepthNetOptions::from(m));
      geo::PoseNetOptions po;
      po.seq_length = config.data.seq_length;
      geo::PoseNet pose(po);
      geo::FlowNet flow(geo::FlowNetOptions::from(m));
      const std::string tag = fr ? "on" : "off";
      Row d{"DepthNet", tag, geo::count_parameters(*depth)}, p{"PoseNet", "-", geo::count_parameters(*pose)},
          f{"FlowNet", tag, geo::count_parameters(*flow)};
      if (!summary) {
        for (torch::nn::Module* net : {static_cast<torch::nn::Module*>(depth.get()),
                                       static_cast<torch::nn::Module*>(pose.get()),
                                       static_cast<torch::nn::Module*>(flow.get())}) {
          net->to(device);
          net->eval();
        }
        torch::InferenceMode guard;
        const auto img = torch::rand({batch, 3, H, W}, device);
        std::vector<torch::Tensor> srcs(config.data.seq_length - 1, img);
        const auto flow_in = torch::rand({batch, 12, H, W}, device);
        spdlog::info("timing FR {} ...", tag);
        d.ms = median_ms([&] { depth(img); }, warmup, iters, device);
        if (fr) p.ms = median_ms([&] { pose(img, srcs); }, warmup, iters, device);
        f.ms = median_ms([&] { flow(flow_in); }, warmup, iters, device);
      }
      rows.push_back(d);
      if (fr) rows.push_back(p);
      rows.push_back(f);
    }

    std::printf("\n%-10s %-4s %14s %12s\n", "network", "FR", "parameters", "ms/batch");
    for (const auto& r : rows) {
      std::printf("%-10s %-4s %14lld %12s\n", r.name.c_str(), r.fr.c_str(), static_cast<long long>(r.params),
                  r.ms < 0 ? "-" : fmt::format("{:.1f}", r.ms).c_str());
    }
    std::printf("\nFR adds %lld parameters to the DepthNet and %lld to the FlowNet.\n",
                static_cast<long long>(rows[0].params - rows[3].params),
                static_cast<long long>(rows[2].params - rows[4].params));
    if (!summary) {
      std::printf("FR inference overhead: DepthNet %+.1f ms, FlowNet %+.1f ms (batch %d, %s).\n",
                  rows[0].ms - rows[3].ms, rows[2].ms - rows[4].ms, batch, device.str().c_str());
    }
    if (!json_path.empty()) {
      std::string json = "{\n  \"libtorch\": \"" + std::string(TORCH_VERSION) + "\",\n  \"device\": \"" +
                         device.str() + "\",\n  \"threads\": " + std::to_string(nthreads) +
                         ",\n  \"height\": " + std::to_string(H) + ",\n  \"width\": " + std::to_string(W) +
                         ",\n  \"batch\": " + std::to_string(batch) + ",\n  \"networks\": [\n";
      for (size_t i = 0; i < rows.size(); ++i) {
        const auto& r = rows[i];
        json += fmt::format("    {{\"name\": \"{}\", \"fr\": \"{}\", \"parameters\": {}, \"ms\": {}}}{}\n", r.name,
                            r.fr, r.params, r.ms < 0 ? "null" : fmt::format("{:.3f}", r.ms),
                            i + 1 < rows.size() ? "," : "");
      }
      json += "  ]\n}\n";
      geo::write_file_atomic(json_path, json);
      spdlog::info("wrote {}", json_path);
    }
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
  return 0;
}
