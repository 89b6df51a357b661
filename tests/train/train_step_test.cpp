// One training step (train/train_step.h): the LR schedule, MultiTensorAdam against torch::optim::Adam,
// the gradient norm, clipping, bf16 networks with float32 losses.
#include "train/train_step.h"
#include "core/runtime.h"
#include "models/sync_batch_norm.h"

#include <ATen/autocast_mode.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <numeric>

#include <unistd.h>

#include "test_util.h"

namespace geo {
namespace {

namespace fs = std::filesystem;

// Three parameters; the third gets its first gradient at step 3 (so it lags two steps behind).
std::vector<torch::Tensor> adam_params() {
  torch::manual_seed(11);
  return {torch::randn({4, 3}).requires_grad_(), torch::randn({5}).requires_grad_(),
          torch::randn({2, 2, 3}).requires_grad_()};
}

std::vector<torch::Tensor> clones(const std::vector<torch::Tensor>& ps) {
  std::vector<torch::Tensor> out;
  for (const auto& p : ps) out.push_back(p.detach().clone().requires_grad_());
  return out;
}

void set_grads(std::vector<torch::Tensor>& ps, int step) {
  torch::manual_seed(100 + step);
  for (size_t i = 0; i < ps.size(); ++i) {
    auto g = torch::randn_like(ps[i]) * static_cast<double>(i + 1);
    if (i == 2 && step < 3) ps[i].mutable_grad() = torch::Tensor();
    else ps[i].mutable_grad() = g;
  }
}

// Validation weighs every snippet once: 5 snippets in batches of 2 (the loader fills the last batch
// from the start of the list again) score the mean of the 5 validated one at a time. The PoseNet
// predicts no motion (its last layer zeroed), so every pixel stays in view and each snippet's loss

TEST(LrSchedule, ConstantAndStep) {
  StageConfig s;
  s.learning_rate = 1e-3;
  EXPECT_EQ(LrSchedule::of(s).at(123456), 1e-3);
  s.lr_schedule = LrScheduleKind::kStep;
  s.lr_step = 10;
  s.lr_gamma = 0.5;
  const auto l = LrSchedule::of(s);
  EXPECT_EQ(l.at(0), 1e-3);
  EXPECT_EQ(l.at(9), 1e-3);
  EXPECT_EQ(l.at(10), 5e-4);
  EXPECT_EQ(l.at(25), 2.5e-4);
}

TEST(MultiTensorAdam, BitIdenticalToTorchAdamAndStateInterchangeable) {
  auto a = adam_params(), b = clones(a);
  const auto options = torch::optim::AdamOptions(1e-2).betas({0.9, 0.999}).eps(1e-8).weight_decay(0.01);
  MultiTensorAdam fast(a, options);
  torch::optim::Adam reference(b, options);
  for (int step = 1; step <= 5; ++step) {
    set_grads(a, step);
    set_grads(b, step);
    fast.step();
    reference.step();
    for (size_t i = 0; i < a.size(); ++i) EXPECT_TRUE(torch::equal(a[i], b[i])) << "step " << step << " param " << i;
  }
  // The third parameter got gradients from step 3 on: 3 steps, the others 5; its moments are the
  // reference's.
  for (size_t i = 0; i < a.size(); ++i) {
    const auto* mine = adam_state_of(fast, a[i]);
    const auto* theirs = adam_state_of(reference, b[i]);
    ASSERT_TRUE(mine && theirs) << "param " << i;
    EXPECT_EQ(mine->step(), i == 2 ? 3 : 5) << "param " << i;
    EXPECT_EQ(theirs->step(), mine->step()) << "param " << i;
    EXPECT_TRUE(torch::equal(mine->exp_avg_sq(), theirs->exp_avg_sq())) << "param " << i;
  }
  // Saved by one, loaded by the other (the checkpoint format is torch::optim::Adam's): the next
  // update is the same again.
  const auto dir = test::fresh_dir("adam_state");
  torch::serialize::OutputArchive out;
  fast.save(out);
  out.save_to(dir + "/fast.pt");
  auto c = clones(a);
  torch::optim::Adam loaded(c, options);
  torch::serialize::InputArchive in;
  in.load_from(dir + "/fast.pt");
  loaded.load(in);
  set_grads(a, 6);
  set_grads(c, 6);
  fast.step();
  loaded.step();
  for (size_t i = 0; i < a.size(); ++i) EXPECT_TRUE(torch::equal(a[i], c[i])) << "param " << i;
}

TEST(GradientNorm, OneReductionOverAllGradients) {
  std::vector<torch::Tensor> ps{torch::zeros({2}).requires_grad_(), torch::zeros({1}).requires_grad_(),
                                torch::zeros({3}).requires_grad_()};
  ps[0].mutable_grad() = torch::tensor({3.0f, 4.0f});
  ps[1].mutable_grad() = torch::tensor({12.0f});
  // ps[2] has no gradient: left out.
  EXPECT_FLOAT_EQ(gradient_norm(ps).item<float>(), 13.0f);
  EXPECT_FALSE(gradient_norm({ps[2]}).defined());
}

// optimizer.grad_clip: the step reports the norm before clipping and leaves the gradients it
// applied scaled to the bound (torch::nn::utils::clip_grad_norm_'s rule); the losses it reports
// are the loss terms of the step.
TEST(TrainStep, ClipsToTheBoundAndReportsTheNormBefore) {
  torch::manual_seed(5);
  Config c = parse_config("model: {encoder_depth: 18, num_scales: 1}\noptimizer: {grad_clip: 0.001}\n");
  Networks n = Networks::create(NetworkSpec::of(c), false);
  TrainStep step(n, c, c.stages[0]);
  const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  const StepResult r = step.run(tgt, srcs, K, 1e-4);
  ASSERT_TRUE(r.finite);
  EXPECT_GT(r.grad_norm, 0.001);
  const double after = gradient_norm(n.trainable_parameters()).item<double>();
  EXPECT_NEAR(after, 0.001 * r.grad_norm / (r.grad_norm + 1e-6), 1e-7);
  ASSERT_EQ(r.losses.back().first, "total");
  EXPECT_EQ(r.losses.size(), 3u);  // rigid, disp_smooth, total
}

// TrainStep::Mode::kDeviceChecks (the update a CUDA graph captures: no host read until it is done,
// LibTorch's fused Adam) against the eager step, on the CPU: the same loss terms and gradient norm
// at the first step (the same forward and backward), the same first update to float rounding with
// clipping at work, loss terms within 1e-3 for two more steps and the same step counts; a step
// whose gradient is NaN is reported
// as not finite and leaves weights, Adam's moments and step counts as they were, bit for bit.
// LibTorch before 2.4 (no fused Adam): the mode is refused with the reason.
TEST(TrainStep, DeviceChecksMatchTheEagerStep) {
  Config c = parse_config("model: {encoder_depth: 18, num_scales: 1}\noptimizer: {grad_clip: 0.01}\n");
  const auto make = [&c] {
    torch::manual_seed(5);
    return Networks::create(NetworkSpec::of(c), false);
  };
  Networks a = make(), b = make();
  TrainStep eager(a, c, c.stages[0]), checked(b, c, c.stages[0]);
  EXPECT_EQ(eager.mode(), TrainStep::Mode::kEager);  // on the CPU, whatever run.cuda_graphs says
  if (!TrainStep::device_checks_available()) {
    GEO_EXPECT_THROW_WITH(checked.set_mode(TrainStep::Mode::kDeviceChecks), "LibTorch 2.4");
    return;
  }
  GEO_EXPECT_THROW_WITH(checked.set_mode(TrainStep::Mode::kGraphed), "CUDA");
  checked.set_mode(TrainStep::Mode::kDeviceChecks);
  torch::manual_seed(6);
  const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  const auto pa = a.trainable_parameters(), pb = b.trainable_parameters();
  ASSERT_EQ(pa.size(), pb.size());
  std::vector<torch::Tensor> start;
  for (const auto& p : pa) start.push_back(p.detach().clone());
  for (int i = 0; i < 3; ++i) {
    const StepResult ra = eager.run(tgt, srcs, K, 1e-3), rb = checked.run(tgt, srcs, K, 1e-3);
    ASSERT_TRUE(ra.finite && rb.finite) << "step " << i;
    ASSERT_EQ(ra.losses.size(), rb.losses.size());
    for (size_t t = 0; t < ra.losses.size(); ++t) {
      EXPECT_EQ(ra.losses[t].first, rb.losses[t].first);
      const double bound = i == 0 ? 0.0 : 1e-3 * std::abs(ra.losses[t].second);  // the same forward first
      EXPECT_NEAR(ra.losses[t].second, rb.losses[t].second, bound) << ra.losses[t].first << " at step " << i;
    }
    if (i > 0) continue;
    EXPECT_GT(ra.grad_norm, 0.01);  // the clipping is at work
    EXPECT_NEAR(rb.grad_norm, ra.grad_norm, 1e-6 * ra.grad_norm);
    EXPECT_EQ(rb.out.tgt_disp.size(), ra.out.tgt_disp.size());
    // The first update from the same gradients: the same to float rounding (of the update, and of
    // the weight it is added to). Later ones are not compared weight by weight: eq. 16's kinks turn
    // rounding into gradient differences of several per cent, which Adam's normalisation passes on
    // (measured: loss terms 8e-5 apart at the third step).
    for (size_t k = 0; k < pa.size(); ++k) {
      const auto da = pa[k] - start[k], db = pb[k] - start[k];
      const double ulp = std::numeric_limits<float>::epsilon() * start[k].abs().max().item<double>();
      EXPECT_LE((da - db).abs().max().item<double>(), 1e-5 * da.abs().max().item<double>() + 2 * ulp)
          << "parameter " << k;
    }
  }
  for (size_t i = 0; i < pa.size(); ++i) {
    const auto* sa = adam_state_of(eager.optimizer(), pa[i]);
    const auto* sb = adam_state_of(checked.optimizer(), pb[i]);
    ASSERT_TRUE(sa && sb) << i;
    EXPECT_EQ(sb->step(), 3);
    EXPECT_EQ(sb->step(), sa->step());
  }
  std::vector<torch::Tensor> weights, moments;
  for (const auto& p : pb) {
    weights.push_back(p.detach().clone());
    moments.push_back(adam_state_of(checked.optimizer(), p)->exp_avg_sq().clone());
  }
  // A NaN gradient (not a NaN pixel: grid_sample's CPU backward does not survive NaN coordinates,
  // which is why the CPU steps eagerly; tests/cuda feeds the NaN pixel).
  const auto hook = pb[0].register_hook([](const torch::Tensor& g) { return g * std::nan(""); });
  const StepResult skipped = checked.run(tgt, srcs, K, 1e-3);
  pb[0].remove_hook(hook);
  EXPECT_FALSE(skipped.finite);
  EXPECT_TRUE(std::isfinite(skipped.losses.back().second));
  for (size_t i = 0; i < pb.size(); ++i) {
    EXPECT_TRUE(torch::equal(pb[i], weights[i])) << "parameter " << i;
    EXPECT_TRUE(torch::equal(adam_state_of(checked.optimizer(), pb[i])->exp_avg_sq(), moments[i])) << i;
    EXPECT_EQ(adam_state_of(checked.optimizer(), pb[i])->step(), 3);
  }
  EXPECT_TRUE(checked.run(tgt, srcs, K, 1e-3).finite);  // and the next good batch updates again
  EXPECT_EQ(adam_state_of(checked.optimizer(), pb[0])->step(), 4);
  EXPECT_FALSE(torch::equal(pb[0], weights[0]));
  GEO_EXPECT_THROW_WITH(checked.set_mode(TrainStep::Mode::kEager), "has run");
}

// run.precision bf16: the networks run under bf16 autocast, the losses stay float32 and close to
// the fp32 step's; gradients reach every parameter in float32; autocast is off again afterwards.
TEST(Precision, Bf16NetworksWithFloat32Losses) {
  Config c = parse_config("model: {encoder_depth: 18, num_scales: 2}\n");
  StageConfig stage = c.stages[0];
  stage.train = NetworkSet{true, true, true};
  torch::manual_seed(5);
  Networks n = Networks::create(NetworkSpec::of(c), true);
  n.set_modes(stage);
  n.set_trainable(stage);
  const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  const auto fp32 = compute_losses(n, tgt, srcs, K, stage, c).losses.values();
  Config b = parse_config("model: {encoder_depth: 18, num_scales: 2}\nrun: {precision: bf16}\n");
  auto out = compute_losses(n, tgt, srcs, K, stage, b);
  EXPECT_FALSE(autocast_enabled(torch::kCPU));
  EXPECT_EQ(out.tgt_disp[0].scalar_type(), torch::kFloat32);
  EXPECT_EQ(out.fwd_full[0][0].scalar_type(), torch::kFloat32);
  EXPECT_EQ(out.losses.total.scalar_type(), torch::kFloat32);
  const auto bf16 = out.losses.values();
  ASSERT_EQ(bf16.size(), fp32.size());
  EXPECT_NE(bf16.back().second, fp32.back().second);  // the networks did run in bfloat16
  for (size_t i = 0; i < fp32.size(); ++i)            // bfloat16 keeps 8 bits of mantissa
    EXPECT_NEAR(bf16[i].second, fp32[i].second, 0.05 * std::abs(fp32[i].second) + 1e-3) << fp32[i].first;
  out.losses.total.backward();
  for (const auto& p : n.trainable_parameters()) {
    ASSERT_TRUE(p.grad().defined());
    EXPECT_EQ(p.grad().scalar_type(), torch::kFloat32);
    EXPECT_TRUE(torch::isfinite(p.grad()).all().item<bool>());
  }
  GEO_EXPECT_THROW_WITH(parse_config("run: {precision: fp16}\n"), "run.precision", "fp32, tf32, bf16");
  {
    Bf16Autocast on(true, torch::kCPU);
    EXPECT_EQ(torch::conv2d(torch::rand({1, 2, 4, 4}), torch::rand({3, 2, 1, 1})).scalar_type(), torch::kBFloat16);
    Bf16Autocast off(false, torch::kCPU);
    EXPECT_TRUE(autocast_enabled(torch::kCPU));
  }
  EXPECT_FALSE(autocast_enabled(torch::kCPU));
}

}  // namespace
}  // namespace geo
