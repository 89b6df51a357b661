#include "bench/harness.h"

#include <spdlog/spdlog.h>
#include <ATen/core/dispatch/Dispatcher.h>
#include <torch/csrc/autograd/profiler_legacy.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#ifdef GEO_BENCH_CUDA_STATS
#include <c10/cuda/CUDACachingAllocator.h>
#endif

#include "core/logging.h"
#include "models/int8.h"

namespace geo::bench {
namespace {

std::string fmt_num(double v, const char* spec = "{:.1f}") { return v < 0 ? "-" : fmt::format(fmt::runtime(spec), v); }

std::string json_num(double v) { return v < 0 ? "null" : fmt::format("{:.4f}", v); }

// "62%" of the ceiling that applies to the row; "-" when unknown.
std::string fraction(const Row& r, const Ceiling& c) {
  const double achieved = r.gflops_per_s(), ceiling = c.of(r);
  return achieved < 0 || ceiling <= 0 ? "-" : fmt::format("{:.0f}%", 100.0 * achieved / ceiling);
}

}  // namespace

void Memory::reset() const {
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

double Memory::peak_mb() const {
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

void sync(const torch::Device& device) {
  if (device.is_cuda()) torch::cuda::synchronize();
}

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

void print_profile(const std::string& title, const std::function<void()>& fn, int top, bool by_shape) {
  namespace prof = torch::autograd::profiler;
  prof::enableProfilerLegacy(torch::profiler::impl::ProfilerConfig(torch::profiler::impl::ProfilerState::CPU,
                                                                   /*report_input_shapes=*/by_shape, false, false,
                                                                   false));
  fn();
  const auto lists = prof::disableProfilerLegacy();
  struct Stat {
    double self_us = 0, total_us = 0;
    int64_t calls = 0;
  };
  std::map<std::string, Stat> stats;
  double all_us = 0;
  for (const auto& list : lists) {  // one list per thread; ranges nest within a thread
    struct Open {
      const prof::LegacyEvent* e;
      double child_us;
    };
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
        if (!stack.empty()) stack.back().child_us += us;
        else all_us += us;
      }
    }
  }
  std::vector<std::pair<std::string, Stat>> sorted(stats.begin(), stats.end());
  std::sort(sorted.begin(), sorted.end(),
            [](const auto& a, const auto& b) { return a.second.self_us > b.second.self_us; });
  const int width = by_shape ? 90 : 52;
  std::printf("\nprofile: %s (one call, %.0f ms in operators)\n%-*s %7s %10s %10s %6s\n", title.c_str(), all_us / 1e3,
              width, "operator", "calls", "self ms", "total ms", "self%");
  for (int i = 0; i < top && i < static_cast<int>(sorted.size()); ++i) {
    const auto& [name, st] = sorted[i];
    std::printf("%-*s %7lld %10.1f %10.1f %5.1f%%\n", width, name.substr(0, width).c_str(),
                static_cast<long long>(st.calls), st.self_us / 1e3, st.total_us / 1e3,
                100.0 * st.self_us / std::max(all_us, 1.0));
  }
}

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

namespace {

// The fastest of `iters` calls of `f` after two warm-ups, in ms.
template <class F>
double best_ms(const torch::Device& device, int iters, F&& f) {
  std::vector<double> ms;
  for (int i = 0; i < iters + 2; ++i) {
    const auto t0 = std::chrono::steady_clock::now();
    f();
    sync(device);
    if (i >= 2) ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  // The best of the runs: a ceiling is what the machine can do, not what it does on average.
  return *std::min_element(ms.begin(), ms.end());
}

// [n,n] uint8 x [n,n] int8 -> uint8 through quantized::linear (the weights prepacked once, as a
// network's are), GOP/s; < 0 where the engine cannot run it.
double int8_gops(int64_t n, int iters, std::string& engine) {
  engine = geo::select_int8_engine();
  if (engine.empty()) return -1;
  try {
    const auto a = at::quantize_per_tensor(torch::rand({n, n}), 1.0 / 255, 0, torch::kQUInt8);
    const auto w = at::quantize_per_tensor(torch::rand({n, n}) - 0.5, 1.0 / 127, 0, torch::kQInt8);
    auto& dispatcher = c10::Dispatcher::singleton();
    torch::jit::Stack stack{w, c10::IValue()};
    dispatcher.findSchemaOrThrow("quantized::linear_prepack", "").callBoxed(&stack);
    const c10::IValue packed = stack.at(0);
    const auto linear = dispatcher.findSchemaOrThrow("quantized::linear", "");
    // Products of n terms of up to 0.5 in size: an output scale that keeps them within uint8.
    const double scale = 0.5 * static_cast<double>(n) / 255.0 / 4;
    const double ms = best_ms(torch::kCPU, iters, [&] {
      torch::jit::Stack s{a, packed, scale, int64_t{128}};
      linear.callBoxed(&s);
    });
    return 2.0 * static_cast<double>(n) * n * n / 1e9 / (ms / 1000.0);
  } catch (const c10::Error& e) {
    spdlog::warn("int8 ceiling not measured: {}", std::string(e.what_without_backtrace()).substr(0, 200));
    return -1;
  }
}

}  // namespace

std::string Ceiling::describe() const {
  std::string d =
      fmt::format("{0}x{0} matrix product {1:.0f} GFLOP/s {2}, {3:.0f} GFLOP/s bf16", n, fp32, float_name(), bf16);
  if (int8 > 0) d += fmt::format(", {:.0f} GOP/s int8 ({})", int8, int8_engine);
  return d;
}

Ceiling measure_ceiling(const torch::Device& device, int64_t n, int iters) {
  Ceiling c;
  c.n = n;
  c.tf32 = device.is_cuda() && at::globalContext().allowTF32CuBLAS();
  torch::NoGradGuard no_grad;
  for (const bool bf16 : {false, true}) {
    const auto dtype = bf16 ? torch::kBFloat16 : torch::kFloat32;
    const auto a = torch::rand({n, n}, torch::TensorOptions().device(device)).to(dtype);
    const auto b = torch::rand({n, n}, torch::TensorOptions().device(device)).to(dtype);
    auto out = torch::empty({n, n}, a.options());
    const double ms = best_ms(device, iters, [&] { torch::mm_out(out, a, b); });
    (bf16 ? c.bf16 : c.fp32) = 2.0 * static_cast<double>(n) * n * n / 1e9 / (ms / 1000.0);
  }
  if (device.is_cpu()) c.int8 = int8_gops(n, iters, c.int8_engine);
  return c;
}

std::string cpu_flags() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("flags", 0) == 0) {
      std::istringstream words(line.substr(line.find(':') + 1));
      std::vector<std::string> present;
      std::string w;
      std::vector<std::string> all;
      while (words >> w) all.push_back(w);
      for (const char* f : {"avx2", "avx512f", "avx512_bf16", "amx_bf16", "amx_tile"})
        if (std::find(all.begin(), all.end(), f) != all.end()) present.emplace_back(f);
      return present.empty() ? "no AVX2" : join_list(present, " ");
    }
  return "unknown";
}

void print_table(const std::vector<Row>& rows, const Ceiling& ceiling) {
  std::printf("\n%-7s %-26s %-3s %5s %12s %9s %9s %9s %9s %8s %8s %5s\n", "section", "what", "FR", "batch",
              "parameters", "GFLOPs", "ms/call", "ms/sample", "samples/s", "peak MB", "GFLOP/s", "ceil");
  for (const auto& r : rows) {
    std::printf("%-7s %-26s %-3s %5lld %12s %9s %9s %9s %9s %8s %8s %5s\n", r.section.c_str(), r.name.c_str(),
                r.fr.c_str(), static_cast<long long>(r.batch), r.params > 0 ? std::to_string(r.params).c_str() : "-",
                fmt_num(r.gflops, "{:.2f}").c_str(), fmt_num(r.ms).c_str(), fmt_num(r.per_sample_ms).c_str(),
                fmt_num(r.samples_per_s).c_str(), fmt_num(r.peak_mb, "{:.0f}").c_str(),
                fmt_num(r.gflops_per_s(), "{:.0f}").c_str(), fraction(r, ceiling).c_str());
  }
  if (ceiling.fp32 > 0)
    std::printf("ceiling: %s (ceil: a row's GFLOP/s as a share of its precision's ceiling)\n",
                ceiling.describe().c_str());
  for (const auto& o : fr_overheads(rows)) std::printf("FR overhead, %s\n", o.c_str());
}

std::string markdown_table(const std::vector<Row>& rows, const Ceiling& ceiling, const std::string& machine,
                           const std::string& command) {
  std::string md = fmt::format("Machine: {}; LibTorch {}; {}.\nCommand: `{}`\n\n", machine, TORCH_VERSION,
                               geo::local_date(), command);
  if (ceiling.fp32 > 0)
    md +=
        fmt::format("Ceiling (same threads): {}. A training step counts 3x its forward FLOPs.\n\n", ceiling.describe());
  md +=
      "| section | what | FR | batch | parameters | GFLOPs | ms/call | ms/sample | samples/s | peak MB | GFLOP/s | of "
      "ceiling |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|---|\n";
  for (const auto& r : rows)
    md += fmt::format("| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n", r.section, r.name, r.fr,
                      r.batch, r.params > 0 ? std::to_string(r.params) : "-", fmt_num(r.gflops, "{:.2f}"),
                      fmt_num(r.ms), fmt_num(r.per_sample_ms), fmt_num(r.samples_per_s), fmt_num(r.peak_mb, "{:.0f}"),
                      fmt_num(r.gflops_per_s(), "{:.0f}"), fraction(r, ceiling));
  const auto overheads = fr_overheads(rows);
  if (!overheads.empty()) {
    md += "\nFR overhead (FR on minus FR off):\n\n";
    for (const auto& o : overheads) md += "- " + o + "\n";
  }
  return md;
}

std::string json_report(const std::vector<Row>& rows, const Ceiling& ceiling, const JsonHeader& h) {
  std::ostringstream js;
  js << "{\n  \"libtorch\": \"" << TORCH_VERSION << "\",\n  \"device\": \"" << h.device
     << "\",\n  \"threads\": " << h.threads << ",\n  \"height\": " << h.height << ",\n  \"width\": " << h.width
     << ",\n  \"bn_folded\": " << (h.bn_folded ? "true" : "false") << ",\n  \"cpu_flags\": \"" << cpu_flags()
     << "\",\n  \"ceiling_gflops_fp32\": " << json_num(ceiling.fp32)
     << ",\n  \"ceiling_gflops_bf16\": " << json_num(ceiling.bf16)
     << ",\n  \"ceiling_gops_int8\": " << json_num(ceiling.int8) << ",\n  \"int8_engine\": \"" << ceiling.int8_engine
     << "\""
     << ",\n  \"ceiling_tf32\": " << (ceiling.tf32 ? "true" : "false") << ",\n  \"rows\": [\n";
  for (size_t i = 0; i < rows.size(); ++i) {
    const auto& r = rows[i];
    const double ceil = ceiling.of(r), achieved = r.gflops_per_s();
    js << fmt::format(
        "    {{\"section\": \"{}\", \"what\": \"{}\", \"fr\": \"{}\", \"batch\": {}, "
        "\"parameters\": {}, \"gflops\": {}, \"ms\": {}, \"ms_per_sample\": {}, "
        "\"samples_per_s\": {}, \"peak_mb\": {}, \"gflops_per_s\": {}, \"of_ceiling\": {}}}{}\n",
        r.section, r.name, r.fr, r.batch, r.params, json_num(r.gflops), json_num(r.ms), json_num(r.per_sample_ms),
        json_num(r.samples_per_s), json_num(r.peak_mb), json_num(achieved),
        json_num(achieved > 0 && ceil > 0 ? achieved / ceil : -1), i + 1 < rows.size() ? "," : "");
  }
  js << "  ]\n}\n";
  return js.str();
}

}  // namespace geo::bench
