// geo_bench's measuring tools: calls timed side by side, peak memory, FLOPs and operator profiles
// through LibTorch's profiler, the machine's matrix-product ceiling, and the table writers.
#pragma once

#include <torch/torch.h>

#include <functional>
#include <string>
#include <utility>
#include <vector>

namespace geo::bench {

// One line of geo_bench's table.
struct Row {
  std::string section;  // params | infer | train | comm | loader | ceiling
  std::string name;
  std::string fr;  // on | off | -
  int64_t batch = 0;
  int64_t params = 0;
  double ms = -1;  // median per call; < 0: not timed
  double per_sample_ms = -1;
  double samples_per_s = -1;
  double peak_mb = -1;
  double gflops = -1;  // per call: one forward pass (params, infer), forward + backward (train: 3x forward)
  bool bf16 = false;   // which ceiling the row is measured against: bf16's, int8's, else fp32's
  bool int8 = false;

  // Achieved GFLOP/s (gflops per call over its median time); < 0 when either is unknown.
  double gflops_per_s() const { return gflops > 0 && ms > 0 ? gflops / (ms / 1000.0) : -1; }
};

// The machine's matrix-product ceiling: GFLOP/s of a large square matrix product (fp32 and bf16),
// the same threads as the rows; < 0 when not measured. int8: GOP/s of the same product in LibTorch's
// quantized engine (uint8 activations x int8 weights -> uint8; CPU only), what an int8 network's
// convolutions run on: `int8_engine` names it (onednn, fbgemm, qnnpack).
struct Ceiling {
  double fp32 = -1;
  double bf16 = -1;
  double int8 = -1;
  std::string int8_engine;
  int64_t n = 0;
  bool tf32 = false;  // CUDA with TF32 allowed (run.precision tf32): the float32 product runs on TF32 tensor cores
  double of(const Row& r) const { return r.int8 ? int8 : r.bf16 ? bf16 : fp32; }
  const char* float_name() const { return tf32 ? "fp32 (TF32)" : "fp32"; }
  std::string describe()
      const;  // "2048x2048 matrix product 205 GFLOP/s fp32, 420 GFLOP/s bf16, 850 GOP/s int8 (onednn)"
};

// Times a [n,n] x [n,n] product in fp32, bf16 and (CPU) int8 on `device`: the fastest of `iters`
// after two warm-ups. The int8 product selects LibTorch's quantized engine for the process (oneDNN
// where it has one, else FBGEMM, else QNNPACK; none: int8 stays unmeasured).
Ceiling measure_ceiling(const torch::Device& device, int64_t n, int iters);

// Peak memory of the process (CPU: resident set high-water mark) or of the caching allocator (CUDA).
class Memory {
 public:
  explicit Memory(const torch::Device& d) : device_(d) {}
  void reset() const;
  double peak_mb() const;

 private:
  torch::Device device_;
};

void sync(const torch::Device& device);

// Times several calls side by side: each is warmed up `warmup` times (at least once), then its peak
// memory is taken over one more call, after the warm-up (the first calls' cuDNN autotuning
// workspaces and one-off allocations are not a steady state's), then the calls take turns for
// `iters` rounds, so a machine that slows down or speeds up affects all of them alike (FR on vs
// off is a difference of a few percent). Fills ms (median), per-sample figures and peak_mb.
void time_side_by_side(const std::vector<std::pair<Row*, std::function<void()>>>& calls, int warmup, int iters,
                       const torch::Device& device);

// FLOPs (in G) of one call as LibTorch's profiler counts them (convolutions, matrix products,
// elementwise add/mul; forward operators only: backward operators are not counted).
double gflops_of(const std::function<void()>& fn);

// Runs `fn` once under LibTorch's profiler and prints the `top` operators by self time (time in the
// operator minus the operators it called), with call counts and inclusive time: where a step goes.
// With `by_shape`, operators are told apart by their input shapes too.
void print_profile(const std::string& title, const std::function<void()>& fn, int top, bool by_shape);

// "AMD EPYC 7B13 (2 logical cores)" and the vector/matrix flags that decide CPU speed
// ("avx2 avx512f avx512_bf16 amx_bf16", those present).
std::string cpu_description();
std::string cpu_flags();

// FR-on minus FR-off of the same row: "infer DepthNet, batch 1: +12.3 ms (+4%)".
std::vector<std::string> fr_overheads(const std::vector<Row>& rows);

void print_table(const std::vector<Row>& rows, const Ceiling& ceiling);
std::string markdown_table(const std::vector<Row>& rows, const Ceiling& ceiling, const std::string& machine,
                           const std::string& command);
struct JsonHeader {
  std::string device;
  int threads = 0;
  int64_t height = 0, width = 0;
  bool bn_folded = true;
};
std::string json_report(const std::vector<Row>& rows, const Ceiling& ceiling, const JsonHeader& header);

}  // namespace geo::bench
