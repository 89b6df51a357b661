// Inference/training shortcuts of the building blocks give the same values as the plain layers.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <condition_variable>
#include <filesystem>
#include <mutex>
#include <thread>

#include "core/runtime.h"
#include "core/state_io.h"
#include "models/conv.h"
#include "models/depth_net.h"
#include "models/flow_net.h"
#include "models/fr.h"
#include "models/conv_bn.h"
#include "models/graph.h"
#include "models/layers.h"
#include "models/prepacked_conv.h"
#include "models/sync_batch_norm.h"
#include "models/upsample_conv.h"

namespace geo {
namespace {

torch::Tensor nearest_x2(const torch::Tensor& x) { return upsample2(x, UpsampleMode::kNearest); }

TEST(Layers, Conv3x3OfUpsampledEqualsConvOfUpsampledImage) {
  torch::manual_seed(3);
  for (auto hw : std::vector<std::pair<int64_t, int64_t>>{{1, 1}, {2, 7}, {5, 4}}) {
    const auto x = torch::randn({2, 3, hw.first, hw.second}, torch::kFloat64).requires_grad_();
    const auto w = torch::randn({4, 3, 3, 3}, torch::kFloat64).requires_grad_();
    const auto b = torch::randn({4}, torch::kFloat64).requires_grad_();
    const auto ref = torch::conv2d(nearest_x2(x), w, b, 1, 1);
    const auto got = conv3x3_of_upsampled(x, w, b);
    ASSERT_EQ(got.sizes(), ref.sizes());
    EXPECT_LT((got - ref).abs().max().item<double>(), 1e-12) << hw.first << "x" << hw.second;
    // Same gradients for x, w and b.
    const auto g = torch::randn_like(ref);
    const auto gr = torch::autograd::grad({ref}, {x, w, b}, {g});
    const auto gg = torch::autograd::grad({got}, {x, w, b}, {g});
    for (int i = 0; i < 3; ++i) EXPECT_LT((gr[i] - gg[i]).abs().max().item<double>(), 1e-11) << i;
  }
  // Without bias.
  const auto x = torch::randn({1, 2, 3, 3}, torch::kFloat64), w = torch::randn({5, 2, 3, 3}, torch::kFloat64);
  EXPECT_LT((conv3x3_of_upsampled(x, w, {}) - torch::conv2d(nearest_x2(x), w, {}, 1, 1)).abs().max().item<double>(),
            1e-12);
  EXPECT_THROW(conv3x3_of_upsampled(x, torch::randn({5, 3, 3, 3}, torch::kFloat64), {}), c10::Error);
}

// Inference's channels-last shortcuts give exactly the plain operations' values: the phases
// interleaved (with and without the ReLU), the decoder's concatenation, a block's add + ReLU.
TEST(Layers, ChannelsLastInferenceShortcutsAreThePlainOperations) {
  torch::manual_seed(4);
  const torch::NoGradGuard no_grad;
  for (auto hw : std::vector<std::pair<int64_t, int64_t>>{{1, 1}, {3, 5}}) {
    const auto phases = torch::randn({2, 2, 2, 6, hw.first + 1, hw.second + 1});
    for (bool relu : {false, true}) {
      const auto got = interleave_phases_channels_last(phases, relu);
      const auto want = relu ? torch::relu(interleave_phases(phases)) : interleave_phases(phases);
      EXPECT_TRUE(got.is_contiguous(at::MemoryFormat::ChannelsLast));
      EXPECT_TRUE(torch::equal(got, want)) << hw.first << "x" << hw.second << (relu ? " relu" : "");
    }
  }
  EXPECT_THROW(interleave_phases_channels_last(torch::zeros({1, 4, 3, 2, 2}), false), c10::Error);
  FloatOps ops;
  const auto a = torch::randn({2, 5, 3, 4}).contiguous(at::MemoryFormat::ChannelsLast);
  const std::vector<torch::Tensor> parts = {a, torch::randn({2, 3, 3, 4}), torch::randn({2, 1, 3, 4})};
  const auto cat = ops.cat(parts);
  EXPECT_TRUE(cat.is_contiguous(at::MemoryFormat::ChannelsLast));
  EXPECT_TRUE(torch::equal(cat, torch::cat(parts, 1)));
  const auto b = torch::randn({2, 5, 3, 4});
  const auto want = torch::relu(a + b);
  EXPECT_TRUE(torch::equal(ops.add_relu(a.clone(), b), want));
}

// geo::conv2d against a float64 convolution (not run by oneDNN), values and gradients, for channel
// counts on either side of oneDNN's blocks of 16, in float32 and bfloat16 (without geo::conv2d's
// padding, LibTorch 2.6 gets a bfloat16 1-channel output and the bfloat16 gradient of a 2- or
// 12-channel input wrong by a third or more).
// Under the poisoned allocator (PoisonedMemory.models_tests) a kernel that reads padding it never
// zeroed fails here.
TEST(Layers, Conv2dIsExactForEveryChannelCount) {
  torch::manual_seed(8);
  for (auto dtype : {torch::kFloat32, torch::kBFloat16})
    for (int64_t k : {1, 3, 7})
      for (int64_t ci : {1, 2, 12, 16, 17, 31, 129})
        for (int64_t co : {1, 2, 12, 16, 17}) {
          const auto x = torch::rand({2, ci, 6, 7}).to(dtype).requires_grad_();
          const auto w = (torch::randn({co, ci, k, k}) / std::sqrt(double(ci * k * k))).to(dtype).requires_grad_();
          const auto b = torch::randn({co}).to(dtype).requires_grad_();
          const auto y = conv2d(x, w, b, {1, 1}, {k / 2, k / 2});
          torch::Tensor y_inference;  // no gradient: the path inference takes
          {
            torch::NoGradGuard no_grad;
            y_inference = conv2d(x, w, b, {1, 1}, {k / 2, k / 2});
          }
          const auto g = torch::randn({2, co, 6, 7}).to(dtype);
          const auto grads = torch::autograd::grad({y}, {x, w, b}, {g});
          const auto x64 = x.detach().to(torch::kFloat64).requires_grad_(),
                     w64 = w.detach().to(torch::kFloat64).requires_grad_(),
                     b64 = b.detach().to(torch::kFloat64).requires_grad_();
          const auto ref = torch::conv2d(x64, w64, b64, 1, k / 2);
          const auto ref_grads = torch::autograd::grad({ref}, {x64, w64, b64}, {g.to(torch::kFloat64)});
          // Relative to the largest value. Without native bfloat16 (cpu_has_fast_bf16) LibTorch sums bfloat16
          // products in bfloat16: up to 16% off at 129 channels x 7x7 there; garbage still fails.
          const double tol = dtype == torch::kFloat32 ? 1e-4 : cpu_has_fast_bf16() ? 0.1 : 0.25;
          const std::string what = c10::str(dtype, " k=", k, " in=", ci, " out=", co);
          ASSERT_EQ(y.sizes(), ref.sizes()) << what;
          for (const auto& out : {y, y_inference})
            EXPECT_LE((out.to(torch::kFloat64) - ref).abs().max().item<double>(),
                      tol * (1 + ref.abs().max().item<double>()))
                << what;
          for (int i = 0; i < 3; ++i)
            EXPECT_LE((grads[i].to(torch::kFloat64) - ref_grads[i]).abs().max().item<double>(),
                      tol * (1 + ref_grads[i].abs().max().item<double>()))
                << what << " gradient " << i;
        }
}

TEST(Layers, FoldedBatchNormGivesTheSameOutputAndRefusesToTrain) {
  torch::manual_seed(4);
  ConvBn cb(3, 6, 3, 2);
  {
    torch::NoGradGuard no_grad;  // non-trivial statistics and affine
    cb->bn->running_mean.uniform_(-1, 1);
    cb->bn->running_var.uniform_(0.5, 2);
    cb->bn->weight.uniform_(0.5, 1.5);
    cb->bn->bias.uniform_(-1, 1);
  }
  cb->eval();
  const auto x = torch::randn({2, 3, 9, 11});
  const auto ref = cb(x).detach();
  EXPECT_FALSE(cb->folded());
  EXPECT_EQ(fold_batchnorm(*cb), 1);
  EXPECT_TRUE(cb->folded());
  EXPECT_FALSE(cb->prepacked());  // oneDNN's kernels are made at the first call, not before
  {  // float32 with oneDNN: the folded kernel is computed where it is used, not held beside the weights
    const auto a = cb->folded_weight(), b = cb->folded_weight();
    EXPECT_TRUE(torch::equal(a, b));
    EXPECT_EQ(a.data_ptr() != b.data_ptr(), at::hasMKLDNN());
  }
  EXPECT_LT((cb(x) - ref).abs().max().item<double>(), 1e-5);
  EXPECT_EQ(cb->prepacked(), at::hasMKLDNN());  // oneDNN-blocked kernels where LibTorch has oneDNN
  // The folded kernel (not kept beside a packed one: computed again when asked) is w * gamma / sqrt(var + eps).
  const auto s = cb->bn->weight / torch::sqrt(cb->bn->running_var + cb->bn->options.eps());
  EXPECT_TRUE(torch::allclose(cb->folded_weight(), cb->conv->weight * s.view({-1, 1, 1, 1}), 1e-6, 1e-7));
  EXPECT_TRUE(torch::allclose(cb->folded_bias(), cb->bn->bias - cb->bn->running_mean * s, 1e-6, 1e-7));
  cb->train();
  EXPECT_THROW(cb(x), c10::Error);
  ConvBn up(3, 4, 3, 1, true, /*upsampled=*/true);  // phase kernels prepacked for forward_upsampled
  up->eval();
  const auto before = up->forward_upsampled(x).detach();
  fold_batchnorm(*up);
  EXPECT_LT((up->forward_upsampled(x) - before).abs().max().item<double>(), 1e-5);
  EXPECT_EQ(up->prepacked(), at::hasMKLDNN());
  // bf16 kernels: within bf16's rounding of the float32 result (the packed path where the CPU has it).
  ConvBn half(3, 4, 3);
  {
    torch::NoGradGuard no_grad;
    half->conv->weight.copy_(up->conv->weight);
  }
  half->eval();
  fold_batchnorm(*half, torch::kBFloat16);
  const auto xb = torch::randn({2, 3, 9, 11});
  const auto want = up->forward_upsampled(xb);
  const auto got = half->forward_upsampled(xb.to(torch::kBFloat16)).to(torch::kFloat32);
  EXPECT_LT((got - want).abs().max().item<double>(), 0.05 * want.abs().max().item<double>());
  EXPECT_LT((before - up(nearest_x2(x))).abs().max().item<double>(), 1e-5);
  // Below kMinSubpixelArea pixels forward_upsampled takes the plain path: same contract.
  const auto small = torch::randn({2, 3, 2, 7});
  ASSERT_LT(small.size(2) * small.size(3), ConvBnImpl::kMinSubpixelArea);
  EXPECT_LT((up->forward_upsampled(small) - up(nearest_x2(small))).abs().max().item<double>(), 1e-5);
}

TEST(Layers, FoldedDepthNetMatchesTheUnfoldedOne) {
  torch::manual_seed(5);
  DepthNetOptions o;
  o.encoder_depth = 18;
  DepthNet net(o);
  net->eval();
  const auto x = torch::rand({1, 3, 64, 208});
  torch::NoGradGuard no_grad;
  const auto ref = net(x).disp;
  fold_batchnorm(*net);
  const auto folded = net(x).disp;  // (float32 with oneDNN: prepacked convolutions, channels-last inside)
  const int threads = at::get_num_threads();
  at::set_num_threads(threads == 1 ? 2 : 1);
  const auto other_threads = net(x).disp;  // the same to the bit: geo_eval and Python agree
  at::set_num_threads(threads);
  ASSERT_EQ(folded.size(), ref.size());
  for (size_t s = 0; s < ref.size(); ++s) {
    EXPECT_LT((folded[s] - ref[s]).abs().max().item<double>(), 1e-4) << "scale " << s;
    EXPECT_TRUE(folded[s].is_contiguous()) << "scale " << s;  // the dense layout whatever ran inside
    EXPECT_TRUE(torch::equal(other_threads[s], folded[s])) << "scale " << s;
  }
  FlowNetOptions fo;  // two output channels: channels-last would show in the strides
  fo.backbone = o;
  FlowNet flow(fo);
  flow->eval();
  const auto in = torch::rand({1, 12, 64, 96});
  const auto flow_ref = flow(in).flow;
  fold_batchnorm(*flow);
  const auto flow_folded = flow(in).flow;
  for (size_t s = 0; s < flow_ref.size(); ++s) {
    EXPECT_LT((flow_folded[s] - flow_ref[s]).abs().max().item<double>(), 1e-4) << "scale " << s;
    EXPECT_TRUE(flow_folded[s].is_contiguous()) << "scale " << s;
  }
}

// oneDNN's prepacked convolution is the convolution, its ReLU fused, and leaves channels-last
// activations; inputs of either layout and of sizes it was not laid out for give the same.
TEST(Layers, PrepackedConvIsTheConvolutionWithItsReluInChannelsLastOrder) {
  torch::manual_seed(6);
  const auto w = torch::randn({8, 5, 3, 3}), b = torch::randn({8});
  const auto x = torch::randn({2, 5, 9, 11});
  const auto other = torch::randn({1, 5, 16, 7}).contiguous(at::MemoryFormat::ChannelsLast);
  for (const bool relu : {false, true}) {
    const auto c = PrepackedConv::make(w, b, {2, 2}, {1, 1}, x.sizes(), relu);
    ASSERT_EQ(static_cast<bool>(c), at::hasMKLDNN());
    if (!c) continue;
    for (const auto& in : {x, other}) {
      auto ref = torch::conv2d(in, w, b, {2, 2}, {1, 1});
      if (relu) ref = torch::relu(ref);
      const auto y = c(in);
      ASSERT_EQ(y.sizes(), ref.sizes());
      EXPECT_TRUE(y.is_contiguous(at::MemoryFormat::ChannelsLast));
      EXPECT_LT((y - ref).abs().max().item<double>(), 1e-5) << "relu " << relu << ", input " << in.sizes();
    }
    EXPECT_EQ(c(x).lt(0).any().item<bool>(), !relu);
  }
  EXPECT_FALSE(PrepackedConv::make(w.to(torch::kBFloat16), b, {1, 1}, {1, 1}, x.sizes(), true));  // float32 only
  EXPECT_THROW(PrepackedConv()(x), c10::Error);
}

// geo::Conv2d draws the initial weights torch::nn::Conv2d draws, from the same random numbers;
// under UninitialisedWeights (networks whose weights are read next) it draws next to nothing and
// init_weights does nothing, and a network so made holds exactly what is then loaded into it.
TEST(Layers, UninitialisedWeightsAreForNetworksLoadedNext) {
  torch::manual_seed(7);
  torch::nn::Conv2d theirs(torch::nn::Conv2dOptions(5, 7, 3).bias(true));
  const auto after_theirs = torch::rand({4});
  torch::manual_seed(7);
  Conv2d ours(torch::nn::Conv2dOptions(5, 7, 3).bias(true));
  EXPECT_TRUE(torch::equal(theirs->weight, ours->weight));
  EXPECT_TRUE(torch::equal(theirs->bias, ours->bias));
  EXPECT_TRUE(torch::equal(after_theirs, torch::rand({4})));  // the same numbers drawn

  DepthNetOptions o;
  o.encoder_depth = 18;
  torch::manual_seed(5);
  DepthNet saved(o);
  DepthNet loaded{nullptr};
  {
    const UninitialisedWeights scope;
    EXPECT_TRUE(UninitialisedWeights::active());
    loaded = DepthNet(o);
    Conv2d empty(torch::nn::Conv2dOptions(64, 32, 3).stride(2).padding(1));
    EXPECT_EQ(empty->weight.sizes(), (torch::IntArrayRef{32, 64, 3, 3}));
    EXPECT_EQ(empty->bias.sizes(), (torch::IntArrayRef{32}));
    EXPECT_EQ(empty->options.in_channels(), 64);
    EXPECT_EQ(empty->options.out_channels(), 32);
    EXPECT_FALSE(Conv2d(torch::nn::Conv2dOptions(64, 32, 1).bias(false))->bias.defined());
  }
  EXPECT_FALSE(UninitialisedWeights::active());
  const auto a = saved->named_parameters(), b = loaded->named_parameters();
  ASSERT_EQ(a.size(), b.size());
  for (const auto& p : a) EXPECT_EQ(p.value().sizes(), b[p.key()].sizes()) << p.key();
  const auto path = (std::filesystem::temp_directory_path() / "geo_layers_uninitialised.pt").string();
  save_state(*saved, path);
  load_state(*loaded, path);
  std::filesystem::remove(path);
  for (const auto& p : a) EXPECT_TRUE(torch::equal(p.value(), b[p.key()])) << p.key();
  for (const auto& p : saved->named_buffers())
    EXPECT_TRUE(torch::equal(p.value(), loaded->named_buffers()[p.key()])) << p.key();
  saved->eval();
  loaded->eval();
  torch::NoGradGuard no_grad;
  const auto x = torch::rand({1, 3, 64, 96});
  EXPECT_TRUE(torch::equal(saved(x).disp[0], loaded(x).disp[0]));
}

// `n` processes played by threads: each call waits for all n and hands each the total.
class ThreadSum {
 public:
  explicit ThreadSum(int n) : n_(n) {}
  void operator()(torch::Tensor& t) {
    std::unique_lock<std::mutex> lock(m_);
    const int64_t generation = generation_;
    total_ = arrived_ == 0 ? t.clone() : total_ + t;
    if (++arrived_ == n_) {
      result_ = total_;
      arrived_ = 0;
      ++generation_;
      ++calls;
      cv_.notify_all();
    } else {
      cv_.wait(lock, [&] { return generation_ != generation; });
    }
    t.copy_(result_);
  }
  int calls = 0;

 private:
  int n_, arrived_ = 0;
  int64_t generation_ = 0;
  torch::Tensor total_, result_;
  std::mutex m_;
  std::condition_variable cv_;
};

// PyTorch's BatchNorm2d or geo's, with the same settings and affine parameters.
template <class BN = torch::nn::BatchNorm2d>
BN bn_of(int64_t c) {
  BN bn(torch::nn::BatchNormOptions(c).eps(1e-3).momentum(0.3));
  torch::NoGradGuard g;
  bn->weight.copy_(torch::tensor({1.5f, 0.5f, 2.0f}));
  bn->bias.copy_(torch::tensor({0.1f, -0.2f, 0.3f}));
  return bn;
}

TEST(SyncBatchNorm, WithoutAGroupItIsPyTorchsBatchNorm2d) {
  torch::manual_seed(4);
  auto ref = bn_of(3);
  auto ours = bn_of<SyncBatchNorm2d>(3);
  // The same parameters and buffers under the same names: checkpoints load either way.
  std::vector<std::string> ref_names, our_names;
  for (const auto& p : ref->named_parameters()) ref_names.push_back(p.key());
  for (const auto& b : ref->named_buffers()) ref_names.push_back(b.key());
  for (const auto& p : ours->named_parameters()) our_names.push_back(p.key());
  for (const auto& b : ours->named_buffers()) our_names.push_back(b.key());
  EXPECT_EQ(our_names, ref_names);
  for (int step = 0; step < 3; ++step) {  // training: batch statistics, running averages, gradients
    const auto x = torch::randn({2, 3, 4, 5}) * 3 + 1, r = torch::randn({2, 3, 4, 5});
    const auto xa = x.clone().requires_grad_(), xb = x.clone().requires_grad_();
    const auto ya = ref(xa), yb = ours(xb);
    EXPECT_TRUE(torch::equal(ya, yb));
    (ya * r).sum().backward();
    (yb * r).sum().backward();
    EXPECT_TRUE(torch::equal(xa.grad(), xb.grad()));
  }
  EXPECT_TRUE(torch::equal(ref->weight.grad(), ours->weight.grad()));
  EXPECT_TRUE(torch::equal(ref->running_mean, ours->running_mean));
  EXPECT_TRUE(torch::equal(ref->running_var, ours->running_var));
  EXPECT_EQ(ours->num_batches_tracked.item<int64_t>(), 3);
  EXPECT_EQ(ref->num_batches_tracked.item<int64_t>(), 3);
  ref->eval();
  ours->eval();
  const auto x = torch::randn({2, 3, 4, 5});
  EXPECT_TRUE(torch::equal(ref(x), ours(x)));  // running statistics
  EXPECT_EQ(ours->num_batches_tracked.item<int64_t>(), 3);
}

TEST(SyncBatchNorm, TwoProcessesEqualOneOverTheConcatenatedBatch) {
  torch::manual_seed(5);
  const auto x = torch::randn({4, 3, 5, 6}) * 2 + 1, r = torch::randn({4, 3, 5, 6});
  // One process over the whole batch, PyTorch's own BatchNorm.
  auto full = bn_of(3);
  const auto xf = x.clone().requires_grad_();
  const auto yf = full(xf);
  (yf * r).sum().backward();
  // Two processes of two samples each; each backpropagates its own part of the same loss.
  ThreadSum sum(2);
  const auto reduce = std::make_shared<const SumAcrossProcesses>(std::ref(sum));
  std::vector<SyncBatchNorm2d> bns = {bn_of<SyncBatchNorm2d>(3), bn_of<SyncBatchNorm2d>(3)};
  std::vector<torch::Tensor> xs(2), ys(2);
  std::vector<std::thread> threads;
  for (int p = 0; p < 2; ++p)
    threads.emplace_back([&, p] {
      xs[p] = x.narrow(0, 2 * p, 2).clone().requires_grad_();
      ys[p] = sync_batch_norm(xs[p], *bns[p], reduce);
      (ys[p] * r.narrow(0, 2 * p, 2)).sum().backward();
    });
  for (auto& t : threads) t.join();
  EXPECT_EQ(sum.calls, 2);  // statistics forward, gradient sums backward
  auto close = [](const torch::Tensor& a, const torch::Tensor& b) { return torch::allclose(a, b, 1e-5, 1e-5); };
  EXPECT_TRUE(close(torch::cat({ys[0], ys[1]}).detach(), yf.detach()));
  EXPECT_TRUE(close(torch::cat({xs[0].grad(), xs[1].grad()}), xf.grad()));
  EXPECT_TRUE(close(bns[0]->weight.grad() + bns[1]->weight.grad(), full->weight.grad()));
  EXPECT_TRUE(close(bns[0]->bias.grad() + bns[1]->bias.grad(), full->bias.grad()));
  for (const auto& bn : bns) {  // running statistics as one process's (unbiased variance over all 120 values)
    EXPECT_TRUE(close(bn->running_mean, full->running_mean));
    EXPECT_TRUE(close(bn->running_var, full->running_var));
  }
  // Per-process statistics really differ here: what makes the test able to fail.
  auto own = bn_of(3);
  EXPECT_FALSE(close(own(x.narrow(0, 0, 2)), yf.narrow(0, 0, 2).detach()));
}

TEST(SyncBatchNorm, ConvBnUsesItInTrainingOnly) {
  torch::manual_seed(6);
  ConvBn plain(2, 3, 3), synced(2, 3, 3);
  {
    torch::NoGradGuard g;
    synced->conv->weight.copy_(plain->conv->weight);
  }
  int calls = 0;
  auto one = std::make_shared<const SumAcrossProcesses>([&calls](torch::Tensor&) { ++calls; });  // a group of one
  EXPECT_EQ(set_batchnorm_sync(*synced, one), 1);
  const auto x = torch::randn({2, 2, 4, 5});
  EXPECT_TRUE(torch::allclose(synced(x), plain(x), 1e-5, 1e-6));
  EXPECT_EQ(calls, 1);
  synced->eval();
  plain->eval();
  EXPECT_TRUE(torch::allclose(synced(x), plain(x), 1e-5, 1e-6));  // running statistics, no collective
  EXPECT_EQ(calls, 1);
  EXPECT_EQ(set_batchnorm_sync(*synced, nullptr), 1);
  // Every BatchNorm of the networks is one: FR's optional spatial BatchNorm too.
  FeatureRefinementOptions fo(4);
  fo.spatial_bn = true;
  FeatureRefinement fr(fo);
  EXPECT_EQ(set_batchnorm_sync(*fr, one), 1);
  fr->train();
  const auto f = torch::randn({2, 4, 3, 5});
  fr(f);
  EXPECT_EQ(calls, 2);
}

}  // namespace
}  // namespace geo

namespace {

// Running mean after k training steps on a constant batch c from 0: c * (1 - (1 - momentum)^k).
TEST(Layers, BatchNormStyleSetsEpsAndMomentum) {
  for (const auto& [momentum, eps] : {std::pair<double, double>{0.001, 1e-3}, {0.1, 1e-5}}) {
    torch::nn::Sequential seq(geo::SyncBatchNorm2d(2));
    geo::set_batchnorm_style(*seq, eps, momentum);
    auto* bn = seq[0]->as<geo::SyncBatchNorm2d>();
    ASSERT_NE(bn, nullptr);
    EXPECT_EQ(bn->options.eps(), eps);
    seq->train();
    const auto x = torch::full({4, 2, 3, 3}, 2.0, torch::kFloat64);
    seq->to(torch::kFloat64);
    for (int k = 0; k < 3; ++k) seq->forward(x);
    const double want = 2.0 * (1 - std::pow(1 - momentum, 3));
    EXPECT_NEAR(bn->running_mean[0].item<double>(), want, 1e-12) << "momentum " << momentum;
    // Evaluation normalises with eps: (x - mean) / sqrt(var + eps), var(constant) = 0 -> running_var
    // decays from 1 towards 0: (1 - m)^3.
    EXPECT_NEAR(bn->running_var[1].item<double>(), std::pow(1 - momentum, 3), 1e-12);
    seq->eval();
    const double rv = std::pow(1 - momentum, 3);
    EXPECT_NEAR(seq->forward(x)[0][0][0][0].item<double>(), (2.0 - want) / std::sqrt(rv + eps), 1e-9);
  }
  torch::nn::Sequential seq(torch::nn::Conv2d(1, 1, 1), geo::SyncBatchNorm2d(3), geo::SyncBatchNorm2d(4));
  EXPECT_EQ(geo::batchnorm_scales(*seq).size(), 2u);
  EXPECT_EQ(geo::batchnorm_scales(*seq)[1].numel(), 4);
}

}  // namespace
