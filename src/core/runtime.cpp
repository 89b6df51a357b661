#include "core/runtime.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <thread>

#include <ATen/Context.h>
#include <c10/core/CPUAllocator.h>
#include <c10/core/impl/alloc_cpu.h>
#include <ATen/autocast_mode.h>
#include <spdlog/spdlog.h>
#include <torch/cuda.h>
#include <torch/torch.h>
#include <torch/version.h>
#if defined(__GLIBC__)
#include <malloc.h>
#endif
#include <sys/mman.h>
#if defined(__x86_64__) || defined(__i386__)
#include <cpuid.h>
#endif

namespace geo {

namespace {
constexpr size_t kHugePage = size_t{2} << 20;

// Blocks of 2 MiB and more start on a 2 MiB boundary and their whole 2 MiB pages are advised huge
// (the tail stays in small pages: no memory is added); freed with free() like LibTorch's own.
c10::DataPtr huge_or_small_block(size_t bytes) {
  void* p = nullptr;
  if (bytes >= kHugePage && posix_memalign(&p, kHugePage, bytes) == 0)
    madvise(p, bytes / kHugePage * kHugePage, MADV_HUGEPAGE);
  else p = c10::alloc_cpu(bytes);  // (and LibTorch's out-of-memory error)
  return {p, p, &c10::free_cpu, c10::Device(c10::DeviceType::CPU)};
}

class HugePageCpuAllocator final : public c10::Allocator {
 public:
#if TORCH_VERSION_MAJOR > 2 || (TORCH_VERSION_MAJOR == 2 && TORCH_VERSION_MINOR >= 3)
  // (LibTorch 2.3 made allocate non-const and added copy_data.)
  c10::DataPtr allocate(size_t bytes) override { return huge_or_small_block(bytes); }
  void copy_data(void* dest, const void* src, std::size_t count) const override { default_copy_data(dest, src, count); }
#else
  c10::DataPtr allocate(size_t bytes) const override { return huge_or_small_block(bytes); }
#endif
  c10::DeleterFnPtr raw_deleter() const override { return &c10::free_cpu; }
};
}  // namespace

HugePages::HugePages() {
  const char* env = std::getenv("GEO_HUGE_PAGES");
  if (env && std::strcmp(env, "0") == 0) return;
  std::ifstream mode("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string modes;
  if (!std::getline(mode, modes) || modes.find("[never]") != std::string::npos) return;
  static HugePageCpuAllocator allocator;
  if (c10::GetCPUAllocator() == &allocator) return;  // (one already alive)
  replaced_ = c10::GetCPUAllocator();
  c10::SetCPUAllocator(&allocator);
}

HugePages::~HugePages() {
  if (replaced_) c10::SetCPUAllocator(replaced_);
}

void keep_freed_memory() {
  const char* env = std::getenv("GEO_KEEP_MEMORY");
  if (env && std::strcmp(env, "0") == 0) return;
#if defined(__GLIBC__)
  mallopt(M_MMAP_MAX, 0);         // large blocks from the heap, reusable after free
  mallopt(M_TRIM_THRESHOLD, -1);  // and never trimmed (-1: "disables trimming", mallopt(3))
  mallopt(M_TOP_PAD, 64 << 20);   // grow the heap in 64 MiB steps
#endif
}

}  // namespace geo

namespace geo {

torch::Device select_device(const std::string& name) {
  if (name == "auto") return torch::cuda::is_available() ? torch::Device(torch::kCUDA, 0) : torch::Device(torch::kCPU);
  if (name == "cpu") return torch::kCPU;
  if (name == "cuda" || name.rfind("cuda:", 0) == 0) {
    if (!torch::cuda::is_available())
      throw std::runtime_error("device '" + name + "' requested, but CUDA is not available here (LibTorch " +
                               std::string(TORCH_VERSION) +
                               " built without CUDA, or no GPU visible); use --device cpu or auto");
    torch::Device d(torch::kCUDA, 0);
    if (name.size() > 5) {
      try {
        d = torch::Device(name);
      } catch (const c10::Error&) {
        throw std::runtime_error("device '" + name + "' is not a device name (auto, cpu, cuda, cuda:N)");
      }
    }
    const auto count = static_cast<int64_t>(torch::cuda::device_count());
    if (d.index() >= count)
      throw std::runtime_error("device '" + name + "': this machine has " + std::to_string(count) + " CUDA device(s)");
    return d;
  }
  throw std::runtime_error("device '" + name + "' is not one of auto, cpu, cuda, cuda:N");
}

bool cpu_has_fast_bf16() {
#if defined(__x86_64__) || defined(__i386__)
  unsigned a = 0, b = 0, c = 0, d = 0;
  if (__get_cpuid_count(7, 0, &a, &b, &c, &d) && (d & (1u << 22))) return true;  // AMX-BF16
  if (__get_cpuid_count(7, 1, &a, &b, &c, &d) && (a & (1u << 5))) return true;   // AVX512-BF16
#endif
  return false;
}

void apply_precision(Precision precision) {
  const bool tf32 = precision != Precision::kFp32;
  at::globalContext().setAllowTF32CuDNN(tf32);
  at::globalContext().setAllowTF32CuBLAS(tf32);
}

int use_all_cores() {
  // OMP_NUM_THREADS, where set, is the user's choice (LibTorch's default follows it): kept.
  if (const char* omp = std::getenv("OMP_NUM_THREADS"); omp && *omp) return torch::get_num_threads();
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  torch::set_num_threads(cores);
  return cores;
}

int thread_count(int asked, const std::string& what) {
  const int cores = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  if (asked > cores) spdlog::warn("{} {} is more than this machine's {} cores: using {}", what, asked, cores, cores);
  return asked > 0 ? std::min(asked, cores) : cores;
}

int apply_run_settings(const RunConfig& run, const torch::Device& device) {
  const int threads = thread_count(run.threads, "run.threads");
  torch::set_num_threads(threads);
  torch::manual_seed(static_cast<uint64_t>(run.seed));
  apply_precision(run.precision);
  at::globalContext().setDeterministicCuDNN(run.deterministic);
  if (device.is_cuda()) at::globalContext().setBenchmarkCuDNN(!run.deterministic);
  return threads;
}

// LibTorch 2.4 replaced the per-device autocast functions (set_enabled for CUDA, set_cpu_enabled,
// ...) by ones that take the device type.
#if TORCH_VERSION_MAJOR > 2 || (TORCH_VERSION_MAJOR == 2 && TORCH_VERSION_MINOR >= 4)
#define GEO_AUTOCAST_BY_DEVICE_TYPE 1
#endif

bool autocast_enabled(torch::DeviceType type) {
#ifdef GEO_AUTOCAST_BY_DEVICE_TYPE
  return at::autocast::is_autocast_enabled(type);
#else
  return type == torch::kCUDA ? at::autocast::is_enabled() : at::autocast::is_cpu_enabled();
#endif
}

Bf16Autocast::Bf16Autocast(bool enabled, const torch::Device& device) : enabled_(enabled), type_(device.type()) {
  if (!enabled_) return;
  if (type_ != torch::kCPU && type_ != torch::kCUDA)
    throw std::runtime_error("run.precision bf16: autocast on " + device.str() + " is not supported (cpu or cuda)");
#ifdef GEO_AUTOCAST_BY_DEVICE_TYPE
  was_enabled_ = autocast_enabled(type_);
  was_dtype_ = at::autocast::get_autocast_dtype(type_);
  at::autocast::set_autocast_dtype(type_, at::kBFloat16);
  at::autocast::set_autocast_enabled(type_, true);
#else
  if (type_ == torch::kCUDA) {
    was_enabled_ = autocast_enabled(type_);
    was_dtype_ = at::autocast::get_autocast_gpu_dtype();
    at::autocast::set_autocast_gpu_dtype(at::kBFloat16);
    at::autocast::set_enabled(true);
  } else {
    was_enabled_ = autocast_enabled(type_);
    was_dtype_ = at::autocast::get_autocast_cpu_dtype();
    at::autocast::set_autocast_cpu_dtype(at::kBFloat16);
    at::autocast::set_cpu_enabled(true);
  }
#endif
  at::autocast::increment_nesting();
}

Bf16Autocast::~Bf16Autocast() {
  if (!enabled_) return;
  // The bf16 copies of the weights are cached while autocast is on: dropped here, since the
  // weights change with every update.
  if (at::autocast::decrement_nesting() == 0) at::autocast::clear_cache();
#ifdef GEO_AUTOCAST_BY_DEVICE_TYPE
  at::autocast::set_autocast_enabled(type_, was_enabled_);
  at::autocast::set_autocast_dtype(type_, was_dtype_);
#else
  if (type_ == torch::kCUDA) {
    at::autocast::set_enabled(was_enabled_);
    at::autocast::set_autocast_gpu_dtype(was_dtype_);
  } else {
    at::autocast::set_cpu_enabled(was_enabled_);
    at::autocast::set_autocast_cpu_dtype(was_dtype_);
  }
#endif
}

int64_t available_memory_bytes() {
  std::ifstream in("/proc/meminfo");
  std::string key;
  int64_t kb = 0;
  std::string unit;
  while (in >> key >> kb >> unit)
    if (key == "MemAvailable:") return kb * 1024;
  return -1;
}

void check_memory_available(const std::string& what, double bytes) {
  const int64_t available = available_memory_bytes();
  if (available < 0 || bytes <= static_cast<double>(available)) return;
  char text[160];
  std::snprintf(text, sizeof text, " needs about %.1f GiB, this machine has %.1f GiB available", bytes / (1 << 30),
                static_cast<double>(available) / (1 << 30));
  throw std::runtime_error(what + text);
}

}  // namespace geo
