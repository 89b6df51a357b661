// geo_bench: what geo costs, measured.
//   geo_bench --summary                       parameter counts and FLOPs, FR on and off
//   geo_bench [--config FILE] [--device cpu|cuda] [--batch 1,4] [--fr both|on|off]
//             [--data-root DIR] [--json FILE]
// (a) one training step of each stage of the config (forward, losses, backward, Adam), median of
//     --train-iters after --train-warmup; (b) inference of the DepthNet, PoseNet and FlowNet
//     separately and of the whole pipeline (depth + pose + rigid flow + residual flow of one pair),
//     median of --iters after --warmup, at each --batch; (c) the data loader's samples/s on
//     --data-root (a packed cache, or KITTI raw / a geo_synth world in the OpenCV build).
// Peak memory: the process's peak resident set on CPU (reset before each measurement through
// /proc/self/clear_refs), the caching allocator's peak on CUDA. FLOPs: as counted by LibTorch's
// profiler (convolutions, matrix products, elementwise add/mul) for one forward pass.
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>
#include <torch/csrc/autograd/profiler_legacy.h>
#include <torch/torch.h>

#include <algorithm>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#include <algorithm>
#include <chrono>
#include <ctime>
#include <mutex>

#include <fstream>
#include <functional>
#include <map>
#include <sstream>
#include <thread>

#include "api/model_access.h"
#include "core/config.h"
#include "core/files.h"
#include "core/logging.h"
#include "core/runtime.h"
#include "core/state_io.h"
#include "data/loader.h"
#include "data/packed.h"
#include "geo/geo.h"
#include "geometry/camera.h"
#include "train/distributed.h"
#include "pipeline/networks.h"
#include "train/train_step.h"
#include "app_options.h"
#ifdef GEO_BENCH_PNG
#include "data/training_data.h"
#endif
#ifdef GEO_BENCH_CUDA_STATS
#include <c10/cuda/CUDACachingAllocator.h>
#endif

namespace {

struct Row {
  std::string section;  // params | infer | train | loader
  std::string name;
  std::string fr;       // on | off | -
  int64_t batch = 0;
  int64_t params = 0;
  double ms = -1;       // median per call; < 0: not timed
  double per_sample_ms = -1;
  double samples_per_s = -1;
  double peak_mb = -1;
  double gflops = -1;   // one forward pass
};

class Memory {
 public:
  explicit Memory(const torch::Device& d) : device_(d) {}
  void reset() const {
#ifdef GEO_BENCH_CUDA_STATS
    if (device_.is_cuda()) {
      c10::cuda::CUDACachingAllocator::resetPeakStats(device_.index() < 0 ? 0 : device_.index());
      return;
    }
#endif
#ifdef __GLIBC__
    malloc_trim(0);  // hand back what the process keeps for reuse (core/runtime.h), so the peak is this row's
#endif
    std::ofstream("/proc/self/clear_refs") << "5";  // resets VmHWM (Linux >= 4.0)
  }
  double peak_mb() const {
#ifdef GEO_BENCH_CUDA_STATS
    if (device_.is_cuda()) {
      const auto stats = c10::cuda::CUDACachingAllocator::getDeviceStats(device_.index() < 0 ? 0 : device_.index());
      return static_cast<double>(stats.allocated_bytes[0].peak) / (1 << 20);  // [0]: aggregate
    }
#endif
    if (device_.is_cuda()) return -1;
    std::ifstream in("/proc/self/status");
    std::string line;
    while (std::getline(in, line))
      if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
    return -1;
  }

 private:
  torch::Device device_;
};

void sync(const torch::Device& device) {
  if (device.is_cuda()) torch::cuda::synchronize();
}

// Times several calls side by side: each is warmed up `warmup` times (at least once), then its peak
// memory is taken over one more call, after the warm-up (the first calls' cuDNN autotuning
// workspaces and one-off allocations are not a steady state's), then the calls take turns for
// `iters` rounds, so a machine that slows down or
// speeds up affects all of them alike (FR on vs off is a difference of a few percent). Fills ms
// (median), per-sample figures and peak_mb of each row.
void time_side_by_side(const std::vector<std::pair<Row*, std::function<void()>>>& calls, int warmup, int iters,
                       const torch::Device& device) {
  const Memory mem(device);
  for (const auto& [row, fn] : calls) {
    for (int i = 0; i < std::max(warmup, 1); ++i) fn();
    sync(device);
    mem.reset();
    fn();
    sync(device);
    row->peak_mb = mem.peak_mb();
  }
  std::vector<std::vector<double>> times(calls.size());
  for (int i = 0; i < iters; ++i)
    for (size_t c = 0; c < calls.size(); ++c) {
      const auto t0 = std::chrono::steady_clock::now();
      calls[c].second();
      sync(device);
      times[c].push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
    }
  for (size_t c = 0; c < calls.size(); ++c) {
    Row& row = *calls[c].first;
    std::sort(times[c].begin(), times[c].end());
    row.ms = times[c][times[c].size() / 2];
    row.per_sample_ms = row.ms / static_cast<double>(row.batch);
    row.samples_per_s = 1000.0 / row.per_sample_ms;
  }
}

// FLOPs of one call as LibTorch's profiler counts them.
double gflops_of(const std::function<void()>& fn) {
  namespace prof = torch::autograd::profiler;
  prof::enableProfilerLegacy(torch::profiler::impl::ProfilerConfig(torch::profiler::impl::ProfilerState::CPU,
                                                                   /*report_input_shapes=*/true, false, false,
                                                                   /*with_flops=*/true));
  fn();
  const auto lists = prof::disableProfilerLegacy();
  uint64_t flops = 0;
  for (const auto& list : lists)
    for (auto e : list) flops += e.flops();
  return static_cast<double>(flops) / 1e9;
}

// KITTI-like intrinsics at the network's size (fx = 0.58 W, fy = 1.92 H, centre).
torch::Tensor intrinsics(int64_t B, int64_t H, int64_t W, const torch::Device& device) {
  auto K = geo::kitti_like_intrinsics(H, W).to(torch::kFloat32);
  return K.view({1, 3, 3}).expand({B, 3, 3}).contiguous().to(device);
}

// Runs `fn` once under LibTorch's profiler and prints the `top` operators by self time (time in the
// operator minus the operators it called), with call counts and inclusive time: where a step goes.
// With `by_shape`, operators are told apart by their input shapes too.
void print_profile(const std::string& title, const std::function<void()>& fn, int top, bool by_shape) {
  namespace prof = torch::autograd::profiler;
  prof::enableProfilerLegacy(torch::profiler::impl::ProfilerConfig(torch::profiler::impl::ProfilerState::CPU,
                                                                   /*report_input_shapes=*/by_shape, false, false, false));
  fn();
  const auto lists = prof::disableProfilerLegacy();
  struct Stat { double self_us = 0, total_us = 0; int64_t calls = 0; };
  std::map<std::string, Stat> stats;
  double all_us = 0;
  for (const auto& list : lists) {  // one list per thread; ranges nest within a thread
    struct Open { const prof::LegacyEvent* e; double child_us; };
    std::vector<Open> stack;
    for (const auto& e : list) {
      if (e.kind() == prof::EventKind::PushRange) {
        stack.push_back({&e, 0.0});
      } else if (e.kind() == prof::EventKind::PopRange && !stack.empty()) {
        const Open open = stack.back();
        stack.pop_back();
        const double us = open.e->cpuElapsedUs(e);
        std::string key = open.e->name();
        if (by_shape) {
          std::vector<std::string> dims;
          for (const auto& shape : open.e->shapes())
            if (!shape.empty()) dims.push_back(geo::join_list(shape, "x"));
          key += " " + geo::join_list(dims, ",");
        }
        auto& st = stats[key];
        st.total_us += us;
        st.self_us += us - open.child_us;
        st.calls += 1;
        if (!stack.empty()) stack.back().child_us += us; else all_us += us;
      }
    }
  }
  std::vector<std::pair<std::string, Stat>> sorted(stats.begin(), stats.end());
  std::sort(sorted.begin(), sorted.end(), [](const auto& a, const auto& b) { return a.second.self_us > b.second.self_us; });
  const int width = by_shape ? 90 : 52;
  std::printf("\nprofile: %s (one call, %.0f ms in operators)\n%-*s %7s %10s %10s %6s\n", title.c_str(), all_us / 1e3,
              width, "operator", "calls", "self ms", "total ms", "self%");
  for (int i = 0; i < top && i < static_cast<int>(sorted.size()); ++i) {
    const auto& [name, st] = sorted[i];
    std::printf("%-*s %7lld %10.1f %10.1f %5.1f%%\n", width, name.substr(0, width).c_str(), static_cast<long long>(st.calls),
                st.self_us / 1e3, st.total_us / 1e3, 100.0 * st.self_us / std::max(all_us, 1.0));
  }
}

std::string fmt_num(double v, const char* spec = "{:.1f}") { return v < 0 ? "-" : fmt::format(fmt::runtime(spec), v); }

std::string json_num(double v) { return v < 0 ? "null" : fmt::format("{:.4f}", v); }

// The config with FR switched on or off, and its networks freshly initialised (seed 0) on `device`.
std::pair<geo::Config, geo::Networks> networks_with_fr(const geo::Config& config, bool fr, bool with_flow,
                                                       const torch::Device& device) {
  geo::Config c = config;
  c.model.use_fr = fr;
  torch::manual_seed(0);
  auto nets = geo::Networks::create(geo::NetworkSpec::of(c), with_flow);
  nets.to(device);
  return {c, nets};
}

// The gradient all-reduce of one training step of `stage` between `world` processes (threads of
// this process, each a rank of a Gloo group on 127.0.0.1): what data-parallel training adds per
// step on top of the step itself. ms: median over `iters` after `warmup`, as seen by rank 0.
Row time_allreduce(const geo::Config& config, const geo::StageConfig& stage, bool fr, int world, int warmup, int iters) {
  auto made = networks_with_fr(config, fr, stage.uses_flow(), torch::kCPU);
  made.second.set_trainable(stage);
  const auto params = made.second.trainable_parameters();
  int64_t elements = 0;
  for (const auto& p : params) elements += p.numel();
  Row row{"comm", stage.name + " grads " + std::to_string(world) + "x gloo", fr ? "on" : "off", world, elements};
  geo::DistributedConfig dc;
  dc.timeout_s = 120;
  const int port = geo::free_local_port();
  std::vector<double> times;
  int64_t buckets = 0, bytes = 0;
  std::vector<std::thread> threads;
  std::exception_ptr error;
  std::mutex error_mutex;
  for (int r = 0; r < world; ++r) {
    threads.emplace_back([&, r] {
      try {
        geo::LaunchInfo l;
        l.rank = r;
        l.world_size = world;
        l.master_addr = "127.0.0.1";
        l.master_port = port;
        l.launcher = "geo_bench";
        auto group = geo::ProcessGroup::connect(l, dc, torch::kCPU);
        std::vector<torch::Tensor> mine;
        for (const auto& p : params) {
          auto q = p.detach().clone().requires_grad_(true);
          q.mutable_grad() = torch::randn_like(q);
          mine.push_back(q);
        }
        geo::GradientAverager avg(*group);
        for (int i = 0; i < warmup + iters; ++i) {
          const auto t0 = std::chrono::steady_clock::now();
          avg.average(mine);
          const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
          if (r == 0 && i >= warmup) times.push_back(ms);
        }
        if (r == 0) {
          buckets = avg.buckets();
          bytes = avg.bytes();
        }
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
      }
    });
  }
  for (auto& t : threads) t.join();
  if (error) std::rethrow_exception(error);
  std::sort(times.begin(), times.end());
  row.ms = times[times.size() / 2];
  row.name += ", " + std::to_string(buckets) + " bucket" + (buckets == 1 ? "" : "s") + ", " +
              fmt::format("{:.0f}", static_cast<double>(bytes) / (1 << 20)) + " MB";
  return row;
}

std::vector<geo::StageConfig> stages_to_time(const geo::Config& config, bool config_given) {
  if (config_given) return config.stages;
  geo::StageConfig s1;  // the paper's schedule: stage 1 depth + pose, stage 2 all three jointly
  geo::StageConfig s2;
  s2.name = "stage2";
  s2.train = geo::NetworkSet{true, true, true};
  return {s1, s2};
}

// "AMD EPYC 7B13 (2 cores)": the processor as /proc/cpuinfo names it.
std::string cpu_description() {
  std::ifstream in("/proc/cpuinfo");
  std::string line, model = "unknown CPU";
  while (std::getline(in, line))
    if (line.rfind("model name", 0) == 0) {
      model = line.substr(line.find(':') + 2);
      break;
    }
  return fmt::format("{} ({} logical cores)", model, std::thread::hardware_concurrency());
}

// FR-on minus FR-off of the same row: "+12.3 ms (+4%)"; empty when there is no pair.
std::vector<std::string> fr_overheads(const std::vector<Row>& rows) {
  std::vector<std::string> out;
  for (const auto& on : rows) {
    if (on.fr != "on" || on.ms < 0) continue;
    for (const auto& off : rows)
      if (off.fr == "off" && off.section == on.section && off.name == on.name && off.batch == on.batch)
        out.push_back(fmt::format("{} {}, batch {}: {:+.1f} ms ({:+.0f}%)", on.section, on.name, on.batch,
                                  on.ms - off.ms, 100.0 * (on.ms / off.ms - 1.0)));
  }
  return out;
}

std::string markdown_table(const std::vector<Row>& rows, const std::string& machine, const std::string& command) {
  std::string md = fmt::format("Machine: {}; LibTorch {}; {}.\nCommand: `{}`\n\n", machine, TORCH_VERSION,
                               geo::local_date(), command);
  md += "| section | what | FR | batch | parameters | GFLOPs | ms/call | ms/sample | samples/s | peak MB |\n"
        "|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& r : rows)
    md += fmt::format("| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n", r.section, r.name, r.fr, r.batch,
                      r.params > 0 ? std::to_string(r.params) : "-", fmt_num(r.gflops, "{:.2f}"),
                      fmt_num(r.ms), fmt_num(r.per_sample_ms), fmt_num(r.samples_per_s),
                      fmt_num(r.peak_mb, "{:.0f}"));
  const auto overheads = fr_overheads(rows);
  if (!overheads.empty()) {
    md += "\nFR overhead (FR on minus FR off):\n\n";
    for (const auto& o : overheads) md += "- " + o + "\n";
  }
  return md;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"geo_bench: parameter counts, FLOPs, inference and training-step timings, loader throughput"};
  std::string config_path, device_name = "cpu", json_path, fr_mode = "both", data_root;
  std::vector<int> batches = {1, 4};
  bool summary = false, no_infer = false, no_train = false, no_fold = false, no_comm = false;
  int warmup = 10, iters = 5, train_warmup = 2, train_iters = 5, threads = 0, train_batch = 0, loader_batches = 20,
      profile_top = 0;
  bool profile_shapes = false;
  std::string precision;
  std::vector<std::string> overrides;
  geo::app::add_config_options(app, config_path, overrides,
                               "YAML config (model, data size, stages); default: the paper's settings and its two stages");
  geo::app::add_device_option(app, device_name, "default: cpu");
  app.add_option("--batch", batches, "inference batch sizes, e.g. 1,4")->delimiter(',')->check(geo::app::positive());
  geo::app::add_precision_option(app, precision, {"fp32", "tf32", "bf16"},
                                 "fp32, tf32 or bf16 (run.precision; default: the config's)");
  app.add_option("--train-batch", train_batch, "training batch size (default: each stage's batch_size)");
  app.add_option("--fr", fr_mode, "feature refinement: both, on or off")->check(CLI::IsMember({"both", "on", "off"}));
  app.add_option("--warmup", warmup, "untimed inference runs before timing (fresh memory is slow to touch)")
      ->check(geo::app::non_negative());
  app.add_option("--iters", iters, "timed inference runs (the median is reported)")->check(geo::app::positive());
  app.add_option("--train-warmup", train_warmup, "untimed training steps")->check(geo::app::non_negative());
  app.add_option("--train-iters", train_iters, "timed training steps (median)")->check(geo::app::positive());
  app.add_option("--threads", threads, "intra-op threads (0 = all cores)")->check(geo::app::non_negative());
  app.add_option("--data-root", data_root, "also time the loader on this data (packed cache; PNG data in the OpenCV build)");
  app.add_option("--loader-batches", loader_batches, "batches timed for the loader")->check(geo::app::positive());
  app.add_flag("--no-infer", no_infer, "skip the inference timings");
  app.add_flag("--no-train", no_train, "skip the training-step timings");
  app.add_flag("--no-comm", no_comm, "skip the gradient all-reduce timings (data-parallel training's cost per step)");
  app.add_flag("--no-fold", no_fold, "inference with BatchNorm as separate layers (default: folded into the convolutions)");
  app.add_option("--json", json_path, "also write every row as JSON to this file");
  std::string markdown_path;
  app.add_option("--markdown", markdown_path,
                 "also write the table as markdown (machine, LibTorch version and command in its header)");
  app.add_option("--profile", profile_top,
                 "after timing, profile one more call of each inference/training row and print its N most costly "
                 "operators (self time)")->check(geo::app::non_negative());
  app.add_flag("--profile-shapes", profile_shapes, "--profile tells operators apart by input shapes too");
  app.add_flag("--summary", summary, "only parameter counts and FLOPs, no timings");
  CLI11_PARSE(app, argc, argv);
  geo::keep_freed_memory();

  try {
    geo::setup_logging("info");
    if (!precision.empty()) overrides.push_back("run.precision=" + precision);
    const geo::Config config = config_path.empty() ? geo::parse_config("", "<defaults>", overrides)
                                                   : geo::load_config(geo::resolve_config_path(config_path), overrides);
    geo::apply_precision(config.run.precision);
    const torch::Device device = geo::select_device(device_name);
    if (device.is_cuda()) at::globalContext().setBenchmarkCuDNN(true);  // fixed shapes: autotune once
    const int nthreads = threads > 0 ? threads : static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    torch::set_num_threads(nthreads);
    const int64_t H = config.data.height, W = config.data.width, N = config.data.seq_length - 1;
    spdlog::info("geo_bench: LibTorch {}, device {} ({}), {} threads, {}x{}, {}-frame snippets, encoder ResNet-{}",
                 TORCH_VERSION, device.str(), geo::name_of(config.run.precision), nthreads, H, W, N + 1, config.model.encoder_depth);

    std::vector<bool> frs;
    if (fr_mode != "off") frs.push_back(true);
    if (fr_mode != "on") frs.push_back(false);
    std::vector<Row> rows;

    // Parameter counts and FLOPs (batch 1).
    for (bool fr : frs) {
      auto made = networks_with_fr(config, fr, true, torch::kCPU);
      geo::Networks& nets = made.second;
      nets.prepare_inference(false);
      torch::InferenceMode guard;
      const auto img = torch::rand({1, 3, H, W});
      std::vector<torch::Tensor> srcs(N, img);
      const auto flow_in = torch::rand({1, 12, H, W});
      const auto K = intrinsics(1, H, W, torch::kCPU);
      const std::string tag = fr ? "on" : "off";
      Row d{"params", "DepthNet", tag, 1, geo::count_parameters(*nets.depth)};
      d.gflops = gflops_of([&] { nets.depth(img); });
      rows.push_back(d);
      if (fr) {
        Row p{"params", "PoseNet", "-", 1, geo::count_parameters(*nets.pose)};
        p.gflops = gflops_of([&] { nets.pose(img, srcs); });
        rows.push_back(p);
      }
      Row f{"params", "FlowNet", tag, 1, geo::count_parameters(*nets.flow)};
      f.gflops = gflops_of([&] { nets.flow(flow_in); });
      rows.push_back(f);
      Row all{"params", "pipeline", tag, 1, d.params + geo::count_parameters(*nets.pose) + f.params};
      all.gflops = gflops_of([&] { geo::predict_pair(nets, img, img, K); });
      rows.push_back(all);
    }

    if (!summary && !no_infer) {
      // Each FR variant in float32 and, with --precision bf16, in bfloat16 too (side by side).
      std::vector<std::pair<geo::Config, geo::Networks>> made;
      std::vector<bool> made_fr, made_bf16;
      for (bool fr : frs)
        for (bool bf16 : {false, true}) {
          if (bf16 && config.run.precision != geo::Precision::kBf16) continue;
          made.push_back(networks_with_fr(config, fr, true, device));
          made.back().second.prepare_inference(!no_fold, bf16);
          made_fr.push_back(fr);
          made_bf16.push_back(bf16);
        }
      torch::InferenceMode guard;
      for (int b : batches) {
        spdlog::info("inference, FR {}, batch {} ...", fr_mode, b);
        const auto img = torch::rand({b, 3, H, W}, device), img2 = torch::rand({b, 3, H, W}, device);
        std::vector<torch::Tensor> srcs(N, img2);
        const auto flow_in = torch::rand({b, 12, H, W}, device);
        const auto K = intrinsics(b, H, W, device);
        std::vector<Row> batch_rows;
        batch_rows.reserve(5 * made.size());
        std::vector<std::pair<Row*, std::function<void()>>> calls;
        // One kind of call at a time (DepthNet, PoseNet, ...), its FR variants side by side.
        // The library path: geo::Model::depth on a uint8 [3,H,W] frame (its conversion, the network,
        // the depth at the frame's size), beside the DepthNet's own forward above.
        const auto frame8 = (img * 255).to(torch::kUInt8);
        std::vector<std::unique_ptr<geo::Model>> models;
        for (const std::string what : {"DepthNet", "PoseNet", "FlowNet", "pipeline", "Model::depth"}) {
          calls.clear();
          for (size_t k = 0; k < made.size(); ++k) {
            const bool pose = what == "PoseNet";
            if (pose && made_fr[k] != made_fr[0]) continue;  // no FR in the PoseNet: once per precision
            geo::Networks& nets = made[k].second;
            batch_rows.push_back(Row{"infer", std::string(what) + (made_bf16[k] ? " bf16" : ""),
                                     pose ? "-" : (made_fr[k] ? "on" : "off"), b});
            std::function<void()> fn;
            if (what == "DepthNet") fn = [&nets, &img] { nets.depth(img); };
            if (pose) fn = [&nets, &img, &srcs] { nets.pose(img, srcs); };
            if (what == "FlowNet") fn = [&nets, &flow_in] { nets.flow(flow_in); };
            if (what == "pipeline") fn = [&nets, &img, &img2, &K] { geo::predict_pair(nets, img, img2, K); };
            if (what == "Model::depth") {  // the library's call: an 8-bit RGB frame in, depth at its size out
              models.push_back(std::make_unique<geo::Model>(geo::ModelAccess::untrained(
                  geo::NetworkSpec::of(made[k].first), "untrained", device.str(), made_bf16[k] ? "bf16" : "fp32")));
              fn = [m = models.back().get(), &frame8] { m->depth(frame8); };
            }
            calls.emplace_back(&batch_rows.back(), fn);
            if (profile_top > 0 && (what == "DepthNet" || what == "pipeline"))
              print_profile(fmt::format("{} inference, FR {}, batch {}", what, batch_rows.back().fr, b), fn,
                            profile_top, profile_shapes);
          }
          time_side_by_side(calls, warmup, iters, device);
        }
        rows.insert(rows.end(), batch_rows.begin(), batch_rows.end());
      }
    }

    if (!summary && !no_train) {
      for (const auto& stage : stages_to_time(config, !config_path.empty())) {
        const int64_t b = train_batch > 0 ? train_batch : stage.batch_size;
        const auto tgt = torch::rand({b, 3, H, W}, device), srcs = torch::rand({b, N, 3, H, W}, device);
        const auto K = intrinsics(b, H, W, device);
        struct Trainee {  // held by pointer: the TrainStep refers to the config and networks
          geo::Config config;
          geo::Networks nets;
          std::unique_ptr<geo::TrainStep> step;
          Row row;
        };
        std::vector<std::unique_ptr<Trainee>> trainees;
        for (bool fr : frs) {
          auto made = networks_with_fr(config, fr, stage.uses_flow(), device);
          auto t = std::make_unique<Trainee>(
              Trainee{made.first, made.second, nullptr, Row{"train", stage.name + " step", fr ? "on" : "off", b}});
          t->step = std::make_unique<geo::TrainStep>(t->nets, t->config, stage);
          trainees.push_back(std::move(t));
        }
        spdlog::info("training step {} [{}], FR {}, batch {} ...", stage.name, geo::join_list(stage.train.names(), ","), fr_mode, b);
        std::vector<std::pair<Row*, std::function<void()>>> calls;
        for (auto& t : trainees) {
          // The trainer's own step (loss, backward, finiteness check, clipping, Adam).
          calls.emplace_back(&t->row, [&t, &tgt, &srcs, &K, &stage] {
            t->step->run(tgt, srcs, K, stage.learning_rate);
          });
        }
        time_side_by_side(calls, train_warmup, train_iters, device);
        for (size_t k = 0; k < trainees.size(); ++k) {
          rows.push_back(trainees[k]->row);
          if (profile_top > 0)
            print_profile(fmt::format("{}, FR {}, batch {}", trainees[k]->row.name, trainees[k]->row.fr, b),
                          calls[k].second, profile_top, profile_shapes);
        }
      }
    }

    // Data-parallel training: the gradient all-reduce each step adds (2 ranks, Gloo, loopback).
    if (!summary && !no_train && !no_comm && geo::distributed_available()) {
      for (const auto& stage : stages_to_time(config, !config_path.empty())) {
        spdlog::info("gradient all-reduce of {} between 2 ranks (Gloo, 127.0.0.1) ...", stage.name);
        rows.push_back(time_allreduce(config, stage, frs.front(), 2, train_warmup, train_iters));
      }
    }

    if (!summary && !data_root.empty()) {
      geo::DataConfig d = config.data;
      d.root = data_root;
      std::shared_ptr<const geo::SnippetSource> source;
      std::string kind = "packed";
#ifdef GEO_BENCH_PNG
      auto data = geo::open_training_data(d);
      source = data.train;
      kind = data.format;
#else
      if (!geo::is_packed_cache(data_root + "/train"))
        throw std::runtime_error("--data-root " + data_root +
                                 ": this build has no OpenCV; give a packed cache (geo_prepare --out)");
      source = std::make_shared<geo::PackedSnippets>(data_root + "/train");
#endif
      const auto lo = geo::loader_options(d, train_batch > 0 ? train_batch : config.stages.front().batch_size);
      spdlog::info("loader on {} ({}), batch {}, {} worker(s) ...", data_root, kind, lo.batch_size, lo.workers);
      Row r{"loader", "loader (" + kind + ")", "-", lo.batch_size};
      const Memory mem(torch::kCPU);
      mem.reset();
      r.samples_per_s = geo::measure_throughput(source, lo, loader_batches);
      r.per_sample_ms = 1000.0 / r.samples_per_s;
      r.ms = r.per_sample_ms * static_cast<double>(r.batch);
      r.peak_mb = mem.peak_mb();
      rows.push_back(r);
    }

    std::printf("\n%-7s %-22s %-3s %5s %12s %11s %10s %10s %9s %8s\n", "section", "what", "FR", "batch",
                "parameters", "GFLOPs", "ms/call", "ms/sample", "samples/s", "peak MB");
    for (const auto& r : rows) {
      std::printf("%-7s %-22s %-3s %5lld %12s %11s %10s %10s %9s %8s\n", r.section.c_str(), r.name.c_str(),
                  r.fr.c_str(), static_cast<long long>(r.batch), r.params > 0 ? std::to_string(r.params).c_str() : "-",
                  fmt_num(r.gflops, "{:.2f}").c_str(), fmt_num(r.ms).c_str(), fmt_num(r.per_sample_ms).c_str(),
                  fmt_num(r.samples_per_s).c_str(), fmt_num(r.peak_mb, "{:.0f}").c_str());
    }
    for (const auto& o : fr_overheads(rows)) std::printf("FR overhead, %s\n", o.c_str());
    if (!markdown_path.empty()) {
      std::vector<std::string> args(argv, argv + argc);
      args[0] = "geo_bench";
      std::string machine = cpu_description();
      if (device.is_cuda()) machine += ", CUDA device " + std::to_string(device.index() < 0 ? 0 : device.index());
      machine += fmt::format(", {} threads", nthreads);
      geo::write_file_atomic(markdown_path, markdown_table(rows, machine, geo::join_list(args, " ")));
      spdlog::info("wrote {}", markdown_path);
    }
    if (!json_path.empty()) {
      std::ostringstream js;
      js << "{\n  \"libtorch\": \"" << TORCH_VERSION << "\",\n  \"device\": \"" << device.str()
         << "\",\n  \"threads\": " << nthreads << ",\n  \"height\": " << H << ",\n  \"width\": " << W
         << ",\n  \"bn_folded\": " << (no_fold ? "false" : "true") << ",\n  \"rows\": [\n";
      for (size_t i = 0; i < rows.size(); ++i) {
        const auto& r = rows[i];
        js << fmt::format("    {{\"section\": \"{}\", \"what\": \"{}\", \"fr\": \"{}\", \"batch\": {}, "
                          "\"parameters\": {}, \"gflops\": {}, \"ms\": {}, \"ms_per_sample\": {}, "
                          "\"samples_per_s\": {}, \"peak_mb\": {}}}{}\n",
                          r.section, r.name, r.fr, r.batch, r.params, json_num(r.gflops), json_num(r.ms),
                          json_num(r.per_sample_ms), json_num(r.samples_per_s), json_num(r.peak_mb),
                          i + 1 < rows.size() ? "," : "");
      }
      js << "  ]\n}\n";
      geo::write_file_atomic(json_path, js.str());
      spdlog::info("wrote {}", json_path);
    }
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
  return 0;
}
