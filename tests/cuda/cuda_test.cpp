// CUDA against CPU: what scripts/gpu_check.sh runs on a GPU machine. Every test skips when no CUDA
// device is visible (the CPU build and CI compile them, they run where a GPU is).
#include "core/config.h"
#include "train/compute_losses.h"
#include "train/trainer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <sstream>

#include "test_util.h"
#include "train/training_helpers.h"

#define GEO_REQUIRE_CUDA()                                                                 \
  if (!torch::cuda::is_available()) GTEST_SKIP() << "no CUDA device here (scripts/gpu_check.sh runs these on a GPU)"

namespace geo {
namespace {

// fp32 on the GPU: TF32 convolutions and matrix products off for the comparison.
class NoTf32 {
 public:
  NoTf32() : cudnn_(at::globalContext().allowTF32CuDNN()), cublas_(at::globalContext().allowTF32CuBLAS()) {
    at::globalContext().setAllowTF32CuDNN(false);
    at::globalContext().setAllowTF32CuBLAS(false);
  }
  ~NoTf32() {
    at::globalContext().setAllowTF32CuDNN(cudnn_);
    at::globalContext().setAllowTF32CuBLAS(cublas_);
  }

 private:
  bool cudnn_, cublas_;
};

// One fp32 forward + eq. 16 + backward of all three networks on CUDA and on the CPU from the same
// weights and batch: loss terms within 1e-4 relative, all gradients together within 1e-3 relative
// (cuDNN and oneDNN sum in different orders; BatchNorm uses the batch's statistics on both).
TEST(Cuda, Fp32StepMatchesTheCpuStep) {
  GEO_REQUIRE_CUDA();
  NoTf32 fp32;
  Config c = parse_config("model: {encoder_depth: 18}\n");
  StageConfig stage = c.stages[0];
  stage.train = NetworkSet{true, true, true};
  torch::manual_seed(7);
  Networks cpu = Networks::create(NetworkSpec::of(c), true);
  torch::manual_seed(7);
  Networks gpu = Networks::create(NetworkSpec::of(c), true);
  gpu.to(torch::Device(torch::kCUDA, 0));
  for (Networks* n : {&cpu, &gpu}) {
    n->set_modes(stage);
    n->set_trainable(stage);
  }
  torch::manual_seed(8);
  const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  auto a = compute_losses(cpu, tgt, srcs, K, stage, c);
  auto b = compute_losses(gpu, tgt.cuda(), srcs.cuda(), K.cuda(), stage, c);
  a.losses.total.backward();
  b.losses.total.backward();
  const auto va = a.losses.values(), vb = b.losses.values();
  ASSERT_EQ(va.size(), vb.size());
  for (size_t i = 0; i < va.size(); ++i)
    EXPECT_NEAR(vb[i].second, va[i].second, 1e-4 * std::abs(va[i].second)) << va[i].first;
  const auto pa = cpu.trainable_parameters(), pb = gpu.trainable_parameters();
  ASSERT_EQ(pa.size(), pb.size());
  double diff = 0, norm = 0;
  for (size_t i = 0; i < pa.size(); ++i) {
    ASSERT_TRUE(pa[i].grad().defined() && pb[i].grad().defined()) << "parameter " << i;
    diff += (pb[i].grad().cpu() - pa[i].grad()).pow(2).sum().item<double>();
    norm += pa[i].grad().pow(2).sum().item<double>();
  }
  EXPECT_LT(std::sqrt(diff / norm), 1e-3);
}

Config cuda_run_config() {
  return parse_config(R"(
model: {encoder_depth: 18}
data: {format: synthetic, synthetic: {drives: 1, frames_per_drive: 10}, height: 64, width: 208, num_workers: 1}
stages:
  - {name: s1, iterations: 3, train: [depth, pose], batch_size: 2}
  - {name: s2, iterations: 2, train: [depth, pose, flow], batch_size: 2}
logging: {interval: 1, summary_interval: 0, checkpoint_interval: 2, val_interval: 2, keep_last: 5}
run: {threads: 2, seed: 3, device: cuda}
)", "cuda.yaml");
}

// The losses column by column: CUDA's backward sums with atomics (grid_sample, some cuDNN
// algorithms), so two CUDA runs agree to rounding, not bit for bit.
void expect_same_losses(const std::string& a, const std::string& b, double rel) {
  std::istringstream sa(a), sb(b);
  std::string la, lb;
  int rows = 0;
  while (std::getline(sa, la)) {
    ASSERT_TRUE(static_cast<bool>(std::getline(sb, lb))) << "fewer rows than " << a;
    if (rows++ == 0) {
      EXPECT_EQ(la, lb);
      continue;
    }
    std::istringstream fa(la), fb(lb);
    for (std::string x, y; std::getline(fa, x, ',') && std::getline(fb, y, ',');) {
      char* end = nullptr;
      const double vx = std::strtod(x.c_str(), &end);
      if (x.empty() || *end != '\0') {
        EXPECT_EQ(x, y);
        continue;
      }
      EXPECT_NEAR(std::strtod(y.c_str(), nullptr), vx, rel * std::abs(vx) + 1e-7) << "row " << rows;
    }
  }
  EXPECT_FALSE(static_cast<bool>(std::getline(sb, lb))) << "more rows than " << a;
}

// Killed during stage 2 and resumed on CUDA: the same losses as an uninterrupted CUDA run.
TEST(Cuda, ResumeOnCudaContinuesTheRun) {
  GEO_REQUIRE_CUDA();
  const auto r = test::killed_and_resumed(cuda_run_config(), test::fresh_dir("cuda_resume"), 4);
  expect_same_losses(r.whole, r.resumed, 1e-3);
}

// A checkpoint written on CUDA resumes on the CPU, and a CPU one on CUDA.
TEST(Cuda, CheckpointsMoveBetweenCudaAndCpu) {
  GEO_REQUIRE_CUDA();
  const auto base = test::fresh_dir("cuda_cpu");
  for (const auto& [first, then] : {std::pair<const char*, const char*>{"cuda", "cpu"}, {"cpu", "cuda"}}) {
    TrainOptions start, resumed;
    start.run_dir = base + "/from_" + first;
    start.device = first;
    resumed.device = then;
    test::train_until_killed(cuda_run_config(), start, 3);  // in stage 1, after its checkpoint at 2
    ASSERT_EQ(resume(start.run_dir, resumed), 0) << first << " -> " << then;
    const auto rows = test::metrics(start.run_dir);
    EXPECT_EQ(std::count(rows.begin(), rows.end(), '\n'), 6) << first << " -> " << then;  // header + 5
  }
}

}  // namespace
}  // namespace geo
