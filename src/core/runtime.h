// Process-wide settings of geo's programs (most applied at start-up).
#pragma once

#include <c10/core/Allocator.h>
#include <torch/types.h>

#include "core/config.h"

#include <string>

namespace geo {

// The one device policy of every geo program: "auto" = the first CUDA device when CUDA is
// available, else the CPU; "cpu"; "cuda" or "cuda:N" = that GPU, and an error (naming the value and
// what this build/machine has) when CUDA is not available. Anything else is an error.
torch::Device select_device(const std::string& name);

// Keeps freed memory in the process for reuse instead of returning it to the OS (glibc: no
// mmap for large blocks, no heap trimming). A training step allocates gigabytes of activations
// that autograd frees at the end of backward; by default glibc hands every block over 32 MB back
// with munmap and the next step page-faults all of it in again. Measured with geo_bench on the
// 2-core CI machine: the DepthNet's training forward over 12 frames at 128x416 went from 3.3 s to
// 2.1 s; on a virtual machine whose page faults are costly, a training step of the learning check
// (ResNet-18 at 64x208, batch 4) took twice as long without it. The peak memory is unchanged; the
// process simply does not shrink after it. Called by training itself (geo::train and geo::resume:
// geo_train, geo_infer --refine, the library, `import geo`, the tests that train) and by
// geo_bench, which times training steps; not by the tools that only predict: there
// memory let go (an int8 model's float kernels) goes back to the system and the next layer's int8
// kernels do not stack on it (geo_infer's peak with the paper's model in int8: 1.17 -> 0.84 GB).
// GEO_KEEP_MEMORY=0 in the environment turns this off.
void keep_freed_memory();

// While alive, tensors of 2 MiB and more on transparent huge pages: LibTorch's CPU allocator (which
// also gives oneDNN its memory) replaced by one that starts such blocks on a 2 MiB boundary and asks
// the kernel for huge pages for their whole 2 MiB pages (madvise MADV_HUGEPAGE; smaller blocks as
// before; all freed with free(), like LibTorch's own). Fresh memory then costs a page fault per
// 2 MiB instead of per 4 KiB: what opening a model mostly is (reading the file's tensors, packing
// int8 kernels for oneDNN), and on virtual machines a fault can cost ~10 us. The tools open models
// inside one (geo::app::open_model: geo_infer, geo_export); the library leaves LibTorch's allocator alone. Not for what
// comes after: blocks that come and go (a frame's activations, a training step's) are reused from
// the heap either way, and huge pages there measured slower. Nothing changes where the kernel gives
// no huge pages (transparent_hugepage "never") or with GEO_HUGE_PAGES=0 in the environment.
class HugePages {
 public:
  HugePages();
  ~HugePages();
  HugePages(const HugePages&) = delete;
  HugePages& operator=(const HugePages&) = delete;
  bool on() const { return replaced_ != nullptr; }

 private:
  c10::Allocator* replaced_ = nullptr;
};

// LibTorch's intra-op threads set to every core of the machine (std::thread::hardware_concurrency):
// what geo's tools use unless told otherwise (LibTorch's own default can be fewer: one on some
// 2-core machines); OMP_NUM_THREADS in the environment, where set, is kept. Returns the count.
int use_all_cores();

// The thread count to use for `asked` threads (0 = every core): more than the machine's cores is
// said (naming `what`, e.g. "--threads" or "run.threads") and clamped to them; one rule for every
// tool, the training run and the library.
int thread_count(int asked, const std::string& what);

// The memory this machine can give without swapping (MemAvailable of /proc/meminfo), in bytes; -1
// where it cannot be told.
int64_t available_memory_bytes();
// Throws std::runtime_error when `bytes` exceed the available memory: "<what> needs about X GiB,
// this machine has Y GiB available". Nothing where the available memory is unknown.
void check_memory_available(const std::string& what, double bytes);

// Whether this CPU computes bfloat16 natively (AVX512-BF16 or AMX-BF16), checked at run time.
bool cpu_has_fast_bf16();

// run.precision for the whole process: TF32 for CUDA convolutions and matrix products off for
// fp32, on for tf32 and bf16 (no effect on CPU).
void apply_precision(Precision precision);

// A run's process settings, in one place for geo_train and geo_bench: intra-op threads
// (`run.threads`, 0 = all cores; more than the machine's cores is said and clamped), the random
// seed, run.precision (apply_precision) and, on CUDA, cuDNN's autotuning (the shapes are fixed, so
// it tunes once). Returns the number of threads in use.
int apply_run_settings(const RunConfig& run, const torch::Device& device);

// While alive and `enabled`: the operations on `device`'s type run under autocast to bfloat16
// (convolutions and matrix products in bf16, precision-sensitive operations in fp32; PyTorch's
// autocast lists). Wrap only the networks' forward; cast their outputs back to float32.
// Whether autocast is on for the device type (the one query that works on LibTorch 1.13 and 2.x).
bool autocast_enabled(torch::DeviceType type);

class Bf16Autocast {
 public:
  Bf16Autocast(bool enabled, const torch::Device& device);
  ~Bf16Autocast();
  Bf16Autocast(const Bf16Autocast&) = delete;
  Bf16Autocast& operator=(const Bf16Autocast&) = delete;

 private:
  bool enabled_;
  bool was_enabled_ = false;
  at::ScalarType was_dtype_ = at::kBFloat16;
  torch::DeviceType type_;
};

}  // namespace geo
