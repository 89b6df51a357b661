// geo_bench: what geo costs, measured.
//   geo_bench --summary                       parameter counts and FLOPs, FR on and off
//   geo_bench [--config FILE] [--device cpu|cuda] [--batch 1,4] [--fr both|on|off]
//             [--data-root DIR] [--json FILE]
// (a) one training step of each stage of the config (forward, losses, backward, Adam), median of
//     --train-iters after --train-warmup; (b) inference of the DepthNet, PoseNet and FlowNet
//     separately and of the whole pipeline (depth + pose + rigid flow + residual flow of one pair),
//     median of --iters after --warmup, at each --batch; (c) the data loader's samples/s on
//     --data-root (a packed cache, or KITTI raw / a geo_synth world in the OpenCV build); (d) the
//     machine's ceiling (a large fp32 and bf16 matrix product) and each row's share of it.
// Peak memory: the process's peak resident set on CPU (reset before each measurement through
// /proc/self/clear_refs), the caching allocator's peak on CUDA. FLOPs: as counted by LibTorch's
// profiler (convolutions, matrix products, elementwise add/mul) for one forward pass; a training
// step counts 3x the FLOPs of its forward pass (the backward pass computes two products per
// forward product: the gradients of the input and of the weights).
#include <CLI/CLI.hpp>
#include <spdlog/spdlog.h>
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <map>
#include <mutex>
#include <thread>

#include "app_options.h"
#include "bench/harness.h"
#include "core/config.h"
#include "core/files.h"
#include "core/logging.h"
#include "core/runtime.h"
#include "data/loader.h"
#include "data/packed/packed.h"
#include "geo/geo.h"
#include "models/int8.h"
#include "pipeline/networks.h"
#include "train/compute_losses.h"
#include "train/distributed.h"
#include "train/train_step.h"
#ifdef GEO_BENCH_PNG
#include "data/training_data.h"
#endif

namespace {

using geo::bench::Row;

// KITTI-like intrinsics at the network's size, one per batch item.
torch::Tensor intrinsics(int64_t B, int64_t H, int64_t W, const torch::Device& device) {
  auto K = geo::kitti_like_intrinsics(H, W).to(torch::kFloat32);
  return K.view({1, 3, 3}).expand({B, 3, 3}).contiguous().to(device);
}

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
Row time_allreduce(const geo::Config& config, const geo::StageConfig& stage, bool fr, int world, int warmup,
                   int iters) {
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

// "AMD EPYC 7B13 (2 logical cores), 2 threads" (+ the CUDA device).
std::string machine_of(const torch::Device& device, int threads) {
  std::string machine = geo::bench::cpu_description() + " [" + geo::bench::cpu_flags() + "]";
  if (device.is_cuda()) machine += ", CUDA device " + std::to_string(device.index() < 0 ? 0 : device.index());
  return machine + fmt::format(", {} threads", threads);
}

struct Options {
  std::string config_path, device_name = "cpu", json_path, markdown_path, fr_mode = "both", data_root, precision;
  std::vector<std::string> overrides, stages;
  std::vector<int> batches = {1, 4};
  bool summary = false, no_infer = false, no_train = false, no_fold = false, no_comm = false, no_ceiling = false;
  bool profile_shapes = false, int8 = false;
  int warmup = 10, iters = 5, train_warmup = 2, train_iters = 5, threads = 0, train_batch = 0, loader_batches = 20,
      profile_top = 0;
  int64_t ceiling_size = 0;
};

void add_options(CLI::App& app, Options& o) {
  geo::app::add_config_options(
      app, o.config_path, o.overrides,
      "YAML config (model, data size, stages); default: the paper's settings and its two stages");
  geo::app::add_device_option(app, o.device_name, "default: cpu");
  app.add_option("--batch", o.batches, "inference batch sizes, e.g. 1,4 (1..1024)")
      ->delimiter(',')
      ->check(CLI::Range(1, 1024));
  geo::app::add_precision_option(app, o.precision, {"fp32", "tf32", "bf16"},
                                 "fp32, tf32 or bf16 (run.precision; default: the config's)");
  app.add_option("--train-batch", o.train_batch, "training batch size, 1..1024 (default: each stage's batch_size)")
      ->check(CLI::Range(1, 1024));
  app.add_option("--stage", o.stages, "time only these stages' training steps (names, e.g. stage1)")->delimiter(',');
  app.add_option("--fr", o.fr_mode, "feature refinement: both, on or off")->check(CLI::IsMember({"both", "on", "off"}));
  app.add_option("--warmup", o.warmup, "untimed inference runs before timing (fresh memory is slow to touch)")
      ->check(geo::app::non_negative());
  app.add_option("--iters", o.iters, "timed inference runs (the median is reported)")->check(geo::app::positive());
  app.add_option("--train-warmup", o.train_warmup, "untimed training steps")->check(geo::app::non_negative());
  app.add_option("--train-iters", o.train_iters, "timed training steps (median)")->check(geo::app::positive());
  app.add_option("--threads", o.threads, "intra-op threads (0 = all cores)")->check(geo::app::non_negative());
  app.add_option("--data-root", o.data_root,
                 "also time the loader on this data (packed cache; PNG data in the OpenCV build)");
  app.add_option("--loader-batches", o.loader_batches, "batches timed for the loader")->check(geo::app::positive());
  app.add_flag("--no-infer", o.no_infer, "skip the inference timings");
  app.add_flag("--no-train", o.no_train, "skip the training-step timings");
  app.add_flag("--no-comm", o.no_comm, "skip the gradient all-reduce timings (data-parallel training's cost per step)");
  app.add_flag("--int8", o.int8,
               "also time int8 inference (DepthNet, PoseNet, FlowNet, pipeline; calibrated on random frames; CPU)");
  app.add_flag("--no-fold", o.no_fold,
               "inference with BatchNorm as separate layers (default: folded into the convolutions)");
  app.add_flag("--no-ceiling", o.no_ceiling, "skip the matrix-product ceiling (and the rows' share of it)");
  app.add_option("--ceiling-size", o.ceiling_size,
                 "side of the square matrices timed for the ceiling, 64..16384 (default: 2048 on CPU, 8192 on CUDA)")
      ->check(CLI::Range(64, 16384));
  app.add_option("--json", o.json_path, "also write every row as JSON to this file");
  app.add_option("--markdown", o.markdown_path,
                 "also write the table as markdown (machine, LibTorch version and command in its header)");
  app.add_option("--profile", o.profile_top,
                 "after timing, profile one more call of each inference/training row and print its N most costly "
                 "operators (self time)")
      ->check(geo::app::non_negative());
  app.add_flag("--profile-shapes", o.profile_shapes, "--profile tells operators apart by input shapes too");
  app.add_flag("--summary", o.summary, "only parameter counts and FLOPs, no timings");
}

// Parameter counts and FLOPs of each network and of the whole pipeline at batch 1.
std::vector<Row> parameter_rows(const geo::Config& config, const std::vector<bool>& frs) {
  const int64_t H = config.data.height, W = config.data.width, N = config.data.seq_length - 1;
  std::vector<Row> rows;
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
    d.gflops = geo::bench::gflops_of([&] { nets.depth(img); });
    rows.push_back(d);
    if (fr == frs.front()) {  // no FR in the PoseNet: one row
      Row p{"params", "PoseNet", "-", 1, geo::count_parameters(*nets.pose)};
      p.gflops = geo::bench::gflops_of([&] { nets.pose(img, srcs); });
      rows.push_back(p);
    }
    Row f{"params", "FlowNet", tag, 1, geo::count_parameters(*nets.flow)};
    f.gflops = geo::bench::gflops_of([&] { nets.flow(flow_in); });
    rows.push_back(f);
    Row all{"params", "pipeline", tag, 1, d.params + geo::count_parameters(*nets.pose) + f.params};
    all.gflops = geo::bench::gflops_of([&] { geo::predict_pair(nets, img, img, K); });
    rows.push_back(all);
  }
  return rows;
}

// The FLOPs of a batch-1 row of `params` times `batch` (inference scales linearly with the batch).
double gflops_at(const std::vector<Row>& params, const std::string& what, const std::string& fr, int64_t batch) {
  for (const auto& r : params)
    if (r.name == what && (r.fr == fr || r.fr == "-" || fr == "-")) return r.gflops * static_cast<double>(batch);
  return -1;
}

// The networks of `nets` (prepared for inference in float32) calibrated on random inputs of
// `batch` frames and quantized to int8: for timing (the values of random frames are not
// what a model sees; geo::Model calibrates on real frames).
void calibrate_int8(geo::Networks& nets, const geo::Config& config, int64_t batch) {
  torch::InferenceMode guard;
  const int64_t H = config.data.height, W = config.data.width;
  geo::observe_int8(*nets.depth->net);
  nets.depth(torch::rand({batch, 3, H, W}));
  geo::quantize_int8(*nets.depth->net);
  geo::observe_int8(*nets.pose);
  nets.pose(torch::rand({batch, 3, H, W}),
            std::vector<torch::Tensor>(static_cast<size_t>(config.data.seq_length - 1), torch::rand({batch, 3, H, W})));
  geo::quantize_int8(*nets.pose);
  if (nets.flow) {
    geo::observe_int8(*nets.flow->net);
    nets.flow(torch::rand({batch, 12, H, W}) * 2 - 1);
    geo::quantize_int8(*nets.flow->net);
  }
}

// Inference of each network and of the pipeline, each FR variant in float32, (with bf16 precision)
// in bfloat16 and (--int8) in int8, side by side, at each batch size.
std::vector<Row> inference_rows(const geo::Config& config, const std::vector<bool>& frs, const Options& o,
                                const torch::Device& device, const std::vector<Row>& params) {
  const int64_t H = config.data.height, W = config.data.width, N = config.data.seq_length - 1;
  std::vector<std::pair<geo::Config, geo::Networks>> made;
  std::vector<bool> made_fr;
  std::vector<std::string> made_precision;  // fp32, bf16, int8
  for (bool fr : frs)
    for (const std::string precision : {"fp32", "bf16", "int8"}) {
      if (precision == "bf16" && config.run.precision != geo::Precision::kBf16) continue;
      if (precision == "int8" && !o.int8) continue;
      made.push_back(networks_with_fr(config, fr, true, device));
      geo::Networks& nets = made.back().second;
      nets.prepare_inference(!o.no_fold || precision == "int8", precision == "bf16");
      if (precision == "int8") calibrate_int8(nets, config, o.batches.front());
      made_fr.push_back(fr);
      made_precision.push_back(precision);
    }
  torch::InferenceMode guard;
  std::vector<Row> rows;
  for (int b : o.batches) {
    spdlog::info("inference, FR {}, batch {} ...", o.fr_mode, b);
    const auto img = torch::rand({b, 3, H, W}, device), img2 = torch::rand({b, 3, H, W}, device);
    std::vector<torch::Tensor> srcs(N, img2);
    const auto flow_in = torch::rand({b, 12, H, W}, device);
    const auto K = intrinsics(b, H, W, device);
    const std::vector<std::string> kinds = {"DepthNet", "PoseNet",          "FlowNet",
                                            "pipeline", "pipeline graphed", "Model::depth"};
    std::vector<Row> batch_rows;
    batch_rows.reserve(kinds.size() * made.size());  // the timed calls hold pointers to their rows
    // The library path: geo::Model::depth on a uint8 [3,H,W] frame (its conversion, the network,
    // the depth at the frame's size), beside the DepthNet's own forward.
    const auto frame8 = (img * 255).to(torch::kUInt8);
    std::vector<std::unique_ptr<geo::Model>> models;
    std::vector<std::unique_ptr<geo::GraphedPairPredictor>> graphed;
    // One kind of call at a time (DepthNet, PoseNet, ...), its FR variants side by side.
    for (const std::string& what : kinds) {
      if (what == "pipeline graphed" && !(device.is_cuda() && geo::CudaGraphCall::available())) continue;
      std::vector<std::pair<Row*, std::function<void()>>> calls;
      for (size_t k = 0; k < made.size(); ++k) {
        const bool pose = what == "PoseNet";
        if (pose && made_fr[k] != made_fr[0]) continue;  // no FR in the PoseNet: once per precision
        const std::string& precision = made_precision[k];
        geo::Networks& nets = made[k].second;
        Row row{"infer", what + (precision == "fp32" ? "" : " " + precision), pose ? "-" : (made_fr[k] ? "on" : "off"),
                b};
        row.bf16 = precision == "bf16";
        row.int8 = precision == "int8";
        row.gflops = gflops_at(params,
                               what == "Model::depth"       ? "DepthNet"
                               : what == "pipeline graphed" ? "pipeline"
                                                            : what,
                               row.fr, b);
        batch_rows.push_back(row);
        std::function<void()> fn;
        if (what == "DepthNet") fn = [&nets, &img] { nets.depth(img); };
        if (pose) fn = [&nets, &img, &srcs] { nets.pose(img, srcs); };
        if (what == "FlowNet") fn = [&nets, &flow_in] { nets.flow(flow_in); };
        if (what == "pipeline") fn = [&nets, &img, &img2, &K] { geo::predict_pair(nets, img, img2, K); };
        if (what == "pipeline graphed") {  // one CUDA graph: captured during the warm-up, replayed
          graphed.push_back(std::make_unique<geo::GraphedPairPredictor>(nets, device));
          fn = [g = graphed.back().get(), &img, &img2, &K] { (*g)(img, img2, K); };
        }
        if (what == "Model::depth") {  // the library's call: an 8-bit RGB frame in, depth at its size out
          geo::LoadOptions lo;
          lo.device = device.str();
          lo.precision = precision == "int8" ? "fp32" : precision;
          models.push_back(std::make_unique<geo::Model>(geo::Model::create(geo::to_yaml(made[k].first), lo)));
          if (precision == "int8") models.back()->quantize_int8({frame8[0], (img2[0] * 255).to(torch::kUInt8)});
          fn = [m = models.back().get(), &frame8] { m->depth(frame8); };
        }
        calls.emplace_back(&batch_rows.back(), fn);
      }
      geo::bench::time_side_by_side(calls, o.warmup, o.iters, device);
      // After the timing, as --profile says: the first calls make kernels and touch fresh memory.
      if (o.profile_top > 0 && (what == "DepthNet" || what == "pipeline"))
        for (const auto& [row, fn] : calls)
          geo::bench::print_profile(fmt::format("{} inference, FR {}, batch {}", row->name, row->fr, b), fn,
                                    o.profile_top, o.profile_shapes);
    }
    rows.insert(rows.end(), batch_rows.begin(), batch_rows.end());
  }
  return rows;
}

// One training step of each stage (the trainer's own step: losses, backward, finiteness check,
// clipping, Adam), its FR variants side by side.
std::vector<Row> training_rows(const geo::Config& config, const std::vector<geo::StageConfig>& stages,
                               const std::vector<bool>& frs, const Options& o, const torch::Device& device) {
  const int64_t H = config.data.height, W = config.data.width, N = config.data.seq_length - 1;
  std::vector<Row> rows;
  for (const auto& stage : stages) {
    const int64_t b = o.train_batch > 0 ? o.train_batch : stage.batch_size;
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
      Row row{"train", stage.name + " step" + (config.run.precision == geo::Precision::kBf16 ? " bf16" : ""),
              fr ? "on" : "off", b};
      row.bf16 = config.run.precision == geo::Precision::kBf16;
      auto t = std::make_unique<Trainee>(Trainee{made.first, made.second, nullptr, row});
      t->step = std::make_unique<geo::TrainStep>(t->nets, t->config, stage);
      if (t->step->mode() == geo::TrainStep::Mode::kGraphed) t->row.name += " graphed";
      // FLOPs counted in fp32: under autocast the profiler sees each convolution twice (the autocast
      // wrapper and the bf16 call it makes); the arithmetic is the same.
      geo::Config counting = t->config;
      counting.run.precision = geo::Precision::kFp32;
      t->row.gflops = 3.0 * geo::bench::gflops_of([&t, &tgt, &srcs, &K, &stage, &counting] {
                        geo::compute_losses(t->nets, tgt, srcs, K, stage, counting);
                      });
      trainees.push_back(std::move(t));
    }
    spdlog::info("training step {} [{}], FR {}, batch {} ...", stage.name, geo::join_list(stage.train.names(), ","),
                 o.fr_mode, b);
    std::vector<std::pair<Row*, std::function<void()>>> calls;
    for (auto& t : trainees)
      calls.emplace_back(&t->row, [&t, &tgt, &srcs, &K, &stage] { t->step->run(tgt, srcs, K, stage.learning_rate); });
    // A graphed step runs eagerly twice and is captured on its third call: all three untimed.
    const bool graphed = std::any_of(trainees.begin(), trainees.end(),
                                     [](const auto& t) { return t->step->mode() == geo::TrainStep::Mode::kGraphed; });
    geo::bench::time_side_by_side(calls, graphed ? std::max(o.train_warmup, 3) : o.train_warmup, o.train_iters, device);
    for (size_t k = 0; k < trainees.size(); ++k) {
      rows.push_back(trainees[k]->row);
      if (o.profile_top > 0)
        geo::bench::print_profile(fmt::format("{}, FR {}, batch {}", trainees[k]->row.name, trainees[k]->row.fr, b),
                                  calls[k].second, o.profile_top, o.profile_shapes);
    }
  }
  return rows;
}

// The data loader's throughput on `o.data_root`, or on the config's data.videos (decoded once when
// opened; the row times the snippets read from them).
Row loader_row(const geo::Config& config, const Options& o) {
  geo::DataConfig d = config.data;
  if (!o.data_root.empty()) d.root = o.data_root;
  const std::string where = o.data_root.empty() ? "data.videos" : o.data_root;
  std::shared_ptr<const geo::SnippetSource> source;
  std::string kind = "packed";
#ifdef GEO_BENCH_PNG
  auto data = geo::open_training_data(d);
  source = data.train;
  kind = data.format;
#else
  if (!geo::is_packed_cache(o.data_root + "/train"))
    throw std::runtime_error("--data-root " + o.data_root +
                             ": this build has no OpenCV; give a packed cache (geo_prepare --out)");
  source = std::make_shared<geo::PackedSnippets>(o.data_root + "/train");
#endif
  const auto lo = geo::loader_options(d, o.train_batch > 0 ? o.train_batch : config.stages.front().batch_size);
  spdlog::info("loader on {} ({}), batch {}, {} worker(s) ...", where, kind, lo.batch_size, lo.workers);
  Row r{"loader", "loader (" + kind + ")", "-", lo.batch_size};
  const geo::bench::Memory mem(torch::kCPU);
  mem.reset();
  r.samples_per_s = geo::measure_throughput(source, lo, o.loader_batches);
  r.per_sample_ms = 1000.0 / r.samples_per_s;
  r.ms = r.per_sample_ms * static_cast<double>(r.batch);
  r.peak_mb = mem.peak_mb();
  return r;
}

// The whole measurement; `command_line` is written into the markdown report.
int bench(Options& o, const std::string& command_line) {
  geo::keep_freed_memory();  // (it times training steps)
  if (!o.precision.empty()) o.overrides.push_back("run.precision=" + o.precision);
  const std::string config_file = o.config_path.empty() ? "" : geo::resolve_config_path(o.config_path);
  const geo::Config config = config_file.empty() ? geo::parse_config("", "<defaults>", o.overrides)
                                                 : geo::load_config(config_file, o.overrides);
  auto reads = geo::config_reads(config);
  reads.insert(reads.end(), {config_file, o.data_root});
  geo::check_outputs({{"--json", o.json_path}, {"--markdown", o.markdown_path}}, reads);
  const torch::Device device = geo::select_device(o.device_name);
  if (o.int8 && !device.is_cpu())
    throw std::runtime_error("--int8: int8 inference runs on the CPU, not on " + device.str());
  if (o.int8 && geo::select_int8_engine().empty())
    throw std::runtime_error("--int8: this LibTorch has no quantized engine (onednn, x86, fbgemm or qnnpack)");
  geo::RunConfig settings = config.run;  // as geo_train applies them, with --threads
  settings.threads = o.threads;
  const int nthreads = geo::apply_run_settings(settings, device);
  spdlog::info("geo_bench: LibTorch {}, device {} ({}), {} threads, {}x{}, {}-frame snippets, encoder ResNet-{}",
               TORCH_VERSION, device.str(), geo::name_of(config.run.precision), nthreads, config.data.height,
               config.data.width, config.data.seq_length, config.model.encoder_depth);

  std::vector<bool> frs;
  if (o.fr_mode != "off") frs.push_back(true);
  if (o.fr_mode != "on") frs.push_back(false);
  std::vector<geo::StageConfig> stages;
  for (const auto& s : stages_to_time(config, !o.config_path.empty()))
    if (o.stages.empty() || std::find(o.stages.begin(), o.stages.end(), s.name) != o.stages.end()) stages.push_back(s);
  if (stages.empty() && !o.no_train && !o.summary)
    throw std::runtime_error("--stage " + geo::join_list(o.stages, ",") + ": no such stage in the config");

  std::vector<Row> rows = parameter_rows(config, frs);
  const std::vector<Row> params = rows;
  geo::bench::Ceiling ceiling;
  if (!o.summary && !o.no_ceiling) {
    const int64_t n = o.ceiling_size > 0 ? o.ceiling_size : device.is_cuda() ? 8192 : 2048;
    // Three n x n float32 matrices at once (a, b, the product).
    if (!device.is_cuda()) geo::check_memory_available("--ceiling-size " + std::to_string(n), 12.0 * n * n);
    ceiling = geo::bench::measure_ceiling(device, n, 7);
    spdlog::info("ceiling: {}", ceiling.describe());
  }
  if (!o.summary && !o.no_infer) {
    auto r = inference_rows(config, frs, o, device, params);
    rows.insert(rows.end(), r.begin(), r.end());
  }
  if (!o.summary && !o.no_train) {
    auto r = training_rows(config, stages, frs, o, device);
    rows.insert(rows.end(), r.begin(), r.end());
  }
  // Data-parallel training: the gradient all-reduce each step adds (2 ranks, Gloo, loopback).
  if (!o.summary && !o.no_train && !o.no_comm && geo::distributed_available())
    for (const auto& stage : stages) {
      spdlog::info("gradient all-reduce of {} between 2 ranks (Gloo, 127.0.0.1) ...", stage.name);
      rows.push_back(time_allreduce(config, stage, frs.front(), 2, o.train_warmup, o.train_iters));
    }
  if (!o.summary && (!o.data_root.empty() || !config.data.videos.empty())) rows.push_back(loader_row(config, o));

  geo::bench::print_table(rows, ceiling);
  if (!o.markdown_path.empty()) {
    geo::write_file_atomic(o.markdown_path,
                           geo::bench::markdown_table(rows, ceiling, machine_of(device, nthreads), command_line));
    spdlog::info("wrote {}", o.markdown_path);
  }
  if (!o.json_path.empty()) {
    geo::write_file_atomic(
        o.json_path, geo::bench::json_report(
                         rows, ceiling, {device.str(), nthreads, config.data.height, config.data.width, !o.no_fold}));
    spdlog::info("wrote {}", o.json_path);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> args(argv, argv + argc);
  args[0] = "geo_bench";
  return geo::app::run_command<Options>(
      argc, argv,
      "geo_bench: parameter counts, FLOPs, inference and training-step timings, loader throughput, "
      "and each as a share of the machine's matrix-product ceiling",
      add_options, [&](Options& o) { return bench(o, geo::join_list(args, " ")); });
}
