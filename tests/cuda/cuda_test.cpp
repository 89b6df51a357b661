// CUDA against CPU: what scripts/gpu_check.sh runs on a GPU machine. Every test skips when no CUDA
// device is visible (the CPU build and CI compile them, they run where a GPU is).
#include "core/config.h"
#include "train/compute_losses.h"
#include "train/train_step.h"
#include "train/trainer.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <map>
#include <sstream>

#include "test_util.h"
#include "train/training_helpers.h"

#define GEO_REQUIRE_CUDA() \
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

// One fp32 training step (forward, eq. 16, backward of all three networks) from the networks seeded
// alike: the loss terms and each network's gradients (on the CPU).
struct Step {
  std::vector<std::pair<std::string, double>> losses;
  std::map<std::string, std::vector<torch::Tensor>> grads;  // depth, pose, flow: named_parameters order
};
Step fp32_step(const torch::Device& device, const torch::Tensor& tgt, const torch::Tensor& srcs) {
  NoTf32 fp32;
  Config c = parse_config("model: {encoder_depth: 18}\n");
  StageConfig stage = c.stages[0];
  stage.train = NetworkSet{true, true, true};
  torch::manual_seed(7);
  Networks nets = Networks::create(NetworkSpec::of(c), true);
  nets.to(device);
  nets.set_modes(stage);
  nets.set_trainable(stage);
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  auto out = compute_losses(nets, tgt.to(device), srcs.to(device), K.to(device), stage, c);
  out.losses.total.backward();
  Step s;
  s.losses = out.losses.values();
  const std::vector<std::pair<std::string, torch::nn::Module*>> modules = {
      {"depth", nets.depth.get()}, {"pose", nets.pose.get()}, {"flow", nets.flow.get()}};
  for (const auto& [name, m] : modules)
    for (const auto& p : m->parameters())
      if (p.grad().defined()) s.grads[name].push_back(p.grad().cpu());
  return s;
}

// |b - a| / |a| over all gradients of one network.
double gradient_gap(const Step& a, const Step& b, const std::string& net) {
  const auto &ga = a.grads.at(net), &gb = b.grads.at(net);
  EXPECT_EQ(ga.size(), gb.size()) << net;
  double diff = 0, norm = 0;
  for (size_t i = 0; i < ga.size() && i < gb.size(); ++i) {
    diff += (gb[i] - ga[i]).pow(2).sum().item<double>();
    norm += ga[i].pow(2).sum().item<double>();
  }
  return std::sqrt(diff / norm);
}

// CUDA against the CPU. The gradients of this step are not smooth functions of its inputs: eq. 16
// is built of |x| terms (L1 photometric error, smoothness) that have a kink at 0, and of masks
// (occlusion, eq. 13; consistency, eq. 15) that switch at thresholds; at initialisation the
// networks' outputs are nearly flat, so many arguments sit at those kinks and switches. On the CPU
// alone, the target image perturbed by 1e-7 of its value (float32 rounding) moves the gradients by
// ~0.5% (DepthNet) and ~5% (FlowNet); 1e-6, by ~3% and ~12%. cuDNN and oneDNN round differently, so
// a 1e-3 agreement is not to be had (measured on an H200: 1.2%, 1.0%, 5.2%). The test: each
// network's CUDA gradients are within twice the distance that a 1e-6 perturbation on the CPU gives
// (a wrong or missing gradient on CUDA is off by far more), and every loss term within 1e-3.
TEST(Cuda, Fp32StepMatchesTheCpuStep) {
  GEO_REQUIRE_CUDA();
  namespace F = torch::nn::functional;
  torch::manual_seed(8);
  const auto smooth = [](const torch::Tensor& low) {  // frames with image structure, not white noise
    return F::interpolate(
        low,
        F::InterpolateFuncOptions().size(std::vector<int64_t>{64, 128}).mode(torch::kBilinear).align_corners(false));
  };
  const auto tgt = smooth(torch::rand({2, 3, 8, 16}));
  const auto srcs = smooth(torch::rand({4, 3, 8, 16})).view({2, 2, 3, 64, 128});
  const auto perturbed = tgt * (1 + 1e-6 * torch::randn_like(tgt));
  const Step cpu = fp32_step(torch::kCPU, tgt, srcs), cpu_perturbed = fp32_step(torch::kCPU, perturbed, srcs);
  const Step cuda = fp32_step(torch::Device(torch::kCUDA, 0), tgt, srcs);
  ASSERT_EQ(cuda.losses.size(), cpu.losses.size());
  for (size_t i = 0; i < cpu.losses.size(); ++i)
    EXPECT_NEAR(cuda.losses[i].second, cpu.losses[i].second, 1e-3 * std::abs(cpu.losses[i].second))
        << cpu.losses[i].first;
  for (const char* net : {"depth", "pose", "flow"}) {
    const double gap = gradient_gap(cpu, cuda, net), yardstick = gradient_gap(cpu, cpu_perturbed, net);
    std::cout << net << ": CUDA vs CPU gradient gap " << gap
              << ", CPU vs CPU with the input perturbed by 1e-6: " << yardstick << "\n";
    EXPECT_GT(yardstick, 0) << net;
    EXPECT_LT(gap, 2 * yardstick) << net;
  }
}

// run.cuda_graphs: the training step replayed from a CUDA graph against the same update run
// eagerly (TrainStep::Mode::kDeviceChecks), fp32 with cuDNN's deterministic algorithms, all three
// networks trained, clipping at work, a new batch and a new learning rate every step (a graph that
// kept the captured batch or rate fails). Two eager runs of that update differ too: grid_sample's
// backward adds with atomics in no fixed order, and eq. 16's kinks amplify such rounding (see
// above); that difference is the yardstick. Over six steps (two eager warm-ups, the capture, three
// replays) each step's loss terms and the weights' updates at the end are within 3x the yardstick
// (plus 1e-4). Also the first two steps against the eager step of kEager (torch::optim::Adam's
// arithmetic): loss terms within 1e-3. A batch with a NaN pixel: the graph reports it and leaves
// weights, Adam's moments and step counts as they were, bit for bit; the next batch updates again.
// A batch of another size runs eagerly.
TEST(Cuda, GraphedStepMatchesTheEagerStep) {
  GEO_REQUIRE_CUDA();
  NoTf32 fp32;
  const bool was_deterministic = at::globalContext().deterministicCuDNN();
  const bool was_benchmark = at::globalContext().benchmarkCuDNN();
  at::globalContext().setDeterministicCuDNN(true);
  at::globalContext().setBenchmarkCuDNN(false);
  const torch::Device cuda(torch::kCUDA, 0);
  Config c = parse_config("model: {encoder_depth: 18}\noptimizer: {grad_clip: 0.1}\n");
  StageConfig stage = c.stages[0];
  stage.train = NetworkSet{true, true, true};
  struct Run {
    Networks nets;
    std::unique_ptr<TrainStep> step;
    std::vector<std::vector<double>> losses;  // per step
  };
  const auto make = [&](TrainStep::Mode mode) {
    torch::manual_seed(7);
    auto r = std::make_unique<Run>(Run{Networks::create(NetworkSpec::of(c), true), nullptr, {}});
    r->nets.to(cuda);
    r->step = std::make_unique<TrainStep>(r->nets, c, stage);
    if (mode != TrainStep::Mode::kGraphed) r->step->set_mode(mode);
    EXPECT_EQ(r->step->mode(), mode);  // kGraphed: the default on CUDA
    return r;
  };
  auto eager = make(TrainStep::Mode::kEager), device = make(TrainStep::Mode::kDeviceChecks),
       device2 = make(TrainStep::Mode::kDeviceChecks), graphed = make(TrainStep::Mode::kGraphed);
  namespace F = torch::nn::functional;
  const auto smooth = [&cuda](const torch::Tensor& low) {
    return F::interpolate(low, F::InterpolateFuncOptions()
                                   .size(std::vector<int64_t>{64, 128})
                                   .mode(torch::kBilinear)
                                   .align_corners(false))
        .to(cuda);
  };
  const auto K =
      torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1}).to(cuda);
  std::vector<torch::Tensor> start;
  for (const auto& p : device->nets.trainable_parameters()) start.push_back(p.detach().clone());
  torch::Tensor tgt, srcs;
  const auto gap = [](const Run& a, const Run& b, size_t i) {
    double g = 0;
    for (size_t t = 0; t < a.losses[i].size(); ++t)
      g = std::max(g, std::abs(b.losses[i][t] - a.losses[i][t]) / std::abs(a.losses[i][t]));
    return g;
  };
  for (size_t i = 0; i < 6; ++i) {
    torch::manual_seed(100 + static_cast<int>(i));
    tgt = smooth(torch::rand({2, 3, 8, 16}));
    srcs = smooth(torch::rand({4, 3, 8, 16})).view({2, 2, 3, 64, 128});
    const double lr = 1e-3 / static_cast<double>(i + 1);
    for (Run* r : {eager.get(), device.get(), device2.get(), graphed.get()}) {
      const StepResult s = r->step->run(tgt, srcs, K, lr);
      ASSERT_TRUE(s.finite) << "step " << i;
      r->losses.emplace_back();
      for (const auto& [name, v] : s.losses) r->losses.back().push_back(v);
      if (i == 0) {
        EXPECT_GT(s.grad_norm, 0.1);  // clipping at work
      }
    }
    const double yardstick = gap(*device, *device2, i), graph_gap = gap(*device, *graphed, i);
    std::cout << "step " << i << ": loss terms, graphed vs eager " << graph_gap << ", eager vs eager " << yardstick
              << ", eager vs kEager " << gap(*eager, *device, i) << "\n";
    EXPECT_LT(graph_gap, 3 * yardstick + 1e-4) << "step " << i;
    if (i < 2) {
      EXPECT_LT(gap(*eager, *device, i), 1e-3) << "step " << i;
    }
  }
  const auto update_gap = [&start](const Run& a, const Run& b) {
    const auto pa = a.nets.trainable_parameters(), pb = b.nets.trainable_parameters();
    double diff = 0, moved = 0;
    for (size_t i = 0; i < pa.size(); ++i) {
      diff += (pb[i] - pa[i]).pow(2).sum().item<double>();
      moved += (pa[i] - start[i]).pow(2).sum().item<double>();
    }
    EXPECT_GT(moved, 0);
    return std::sqrt(diff / moved);
  };
  const double yardstick = update_gap(*device, *device2), graph_gap = update_gap(*device, *graphed);
  std::cout << "weight updates after 6 steps: graphed vs eager " << graph_gap << ", eager vs eager " << yardstick
            << ", eager vs kEager " << update_gap(*eager, *device) << "\n";
  EXPECT_LT(graph_gap, 3 * yardstick + 1e-4);
  const auto pb = graphed->nets.trainable_parameters();
  for (const auto& p : pb) EXPECT_EQ(adam_state_of(graphed->step->optimizer(), p)->step(), 6);
  TrainStep& graph = *graphed->step;

  std::vector<torch::Tensor> weights, moments;
  for (const auto& p : pb) {
    weights.push_back(p.detach().clone());
    moments.push_back(adam_state_of(graph.optimizer(), p)->exp_avg().clone());
  }
  auto bad = tgt.clone();
  bad.index_put_({1, 2, 10, 20}, std::nan(""));
  EXPECT_FALSE(graph.run(bad, srcs, K, 1e-3).finite);
  for (size_t i = 0; i < pb.size(); ++i) {
    EXPECT_TRUE(torch::equal(pb[i], weights[i])) << "parameter " << i;
    EXPECT_TRUE(torch::equal(adam_state_of(graph.optimizer(), pb[i])->exp_avg(), moments[i])) << i;
    EXPECT_EQ(adam_state_of(graph.optimizer(), pb[i])->step(), 6) << i;
  }
  EXPECT_TRUE(graph.run(tgt, srcs, K, 1e-3).finite);
  EXPECT_EQ(adam_state_of(graph.optimizer(), pb[0])->step(), 7);
  EXPECT_FALSE(torch::equal(pb[0], weights[0]));
  const StepResult other = graph.run(tgt.narrow(0, 0, 1), srcs.narrow(0, 0, 1), K.narrow(0, 0, 1), 1e-3);
  EXPECT_TRUE(other.finite);
  EXPECT_EQ(adam_state_of(graph.optimizer(), pb[0])->step(), 8);
  at::globalContext().setDeterministicCuDNN(was_deterministic);
  at::globalContext().setBenchmarkCuDNN(was_benchmark);
}

// GraphedPairPredictor: a pair's inference replayed from a CUDA graph gives what predict_pair gives
// on the same inputs (the same kernels: equal within 1e-6), for new frames every call (two eager
// calls, the capture, replays), and frames of another size run eagerly.
TEST(Cuda, GraphedPairPredictionEqualsTheEagerOne) {
  GEO_REQUIRE_CUDA();
  NoTf32 fp32;
  const torch::Device cuda(torch::kCUDA, 0);
  Config c = parse_config("model: {encoder_depth: 18}\n");
  torch::manual_seed(9);
  Networks nets = Networks::create(NetworkSpec::of(c), true);
  nets.to(cuda);
  nets.prepare_inference(true, false);
  torch::InferenceMode inference;
  GraphedPairPredictor graphed(nets, cuda);
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).to(cuda);
  for (int i = 0; i < 6; ++i) {
    const int64_t W = i == 5 ? 96 : 128;
    const auto tgt = torch::rand({1, 3, 64, W}, cuda), src = torch::rand({1, 3, 64, W}, cuda);
    const PairPrediction want = predict_pair(nets, tgt, src, K), got = graphed(tgt, src, K);
    for (const auto& [a, b] : {std::pair{want.disp, got.disp},
                               {want.src_from_tgt, got.src_from_tgt},
                               {want.rigid_flow, got.rigid_flow},
                               {want.flow, got.flow}})
      EXPECT_TRUE(torch::allclose(b, a, 1e-6, 1e-6)) << "call " << i << ": " << (b - a).abs().max().item<double>();
  }
}

// fp32 with cuDNN's deterministic algorithms (run.deterministic): with TF32 and autotuning each
// process picks its own algorithms, and a few Adam steps amplify their rounding (measured on an
// H200: the first stage-2 step of two such runs 5% apart in flow smoothness; with this, within 1e-3).
Config cuda_run_config() {
  return parse_config(R"(
model: {encoder_depth: 18}
data: {format: synthetic, synthetic: {drives: 1, frames_per_drive: 10}, height: 64, width: 208, num_workers: 1}
stages:
  - {name: s1, iterations: 3, train: [depth, pose], batch_size: 2}
  - {name: s2, iterations: 2, train: [depth, pose, flow], batch_size: 2}
logging: {interval: 1, summary_interval: 0, checkpoint_interval: 2, val_interval: 2, keep_last: 5}
run: {threads: 2, seed: 3, device: cuda, precision: fp32, deterministic: true}
)",
                      "cuda.yaml");
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

// Killed during stage 2 and resumed on CUDA: the same losses as an uninterrupted CUDA run, to 5e-3.
// The bound is what two uninterrupted runs give: with the update checked on the device (the CUDA
// default, run.cuda_graphs), the flow term after stage 2's first update came out 2.1459 and 2.1513
// in two runs of the same build on an H200 (the rows before it agree to 4 digits).
TEST(Cuda, ResumeOnCudaContinuesTheRun) {
  GEO_REQUIRE_CUDA();
  const auto r = test::killed_and_resumed(cuda_run_config(), test::fresh_dir("cuda_resume"), 4);
  expect_same_losses(r.whole, r.resumed, 5e-3);
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
