// The loss pass (train/compute_losses.h): scales, the full flow against inference's, the learned
// camera, frozen BatchNorm, where the FlowNet input's gradient reaches.
#include "train/compute_losses.h"
#include "train/train_step.h"
#include "models/sync_batch_norm.h"
#include "core/runtime.h"

#include <ATen/autocast_mode.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <numeric>

#include <unistd.h>

#include "test_util.h"

namespace geo {
namespace {

namespace fs = std::filesystem;

TEST(ComputeLosses, NumScalesSetsTheScalesOfEveryTerm) {
  torch::manual_seed(5);
  for (int scales : {1, 4}) {
    Config c = parse_config("model: {encoder_depth: 18, num_scales: " + std::to_string(scales) + "}\n");
    c.stages[0].train = NetworkSet{true, true, true};
    Networks n = Networks::create(NetworkSpec::of(c), true);
    // Batch 2 at 64x128: BatchNorm in training needs more than one value per channel at the
    // PoseNet's 1x1 output.
    const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
    const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
    const auto out = compute_losses(n, tgt, srcs, K, c.stages[0], c);
    EXPECT_EQ(out.tgt_disp.size(), static_cast<size_t>(scales));
    EXPECT_EQ(out.rigid.fwd_flow[1].size(), static_cast<size_t>(scales));
    EXPECT_EQ(out.fwd_full[0].size(), static_cast<size_t>(scales));
    EXPECT_EQ(out.flow->fwd_visible[0].size(), static_cast<size_t>(scales));
    EXPECT_TRUE(std::isfinite(out.losses.total.item<double>()));
  }
}

// Training and inference feed the FlowNet the same input (rigid_flow_net_input): in eval mode the
// training forward's full flow to the next frame equals predict_pair's for the same weights and
// frames. Not bit for bit: training runs the DepthNet over the target and its sources in one batch,
// inference over the target alone, and oneDNN's convolutions round differently per batch size.
TEST(ComputeLosses, FullFlowEqualsInferencesFlow) {
  torch::manual_seed(9);
  Config c = parse_config("model: {encoder_depth: 18, num_scales: 2}\n");
  StageConfig stage = c.stages[0];
  stage.train = NetworkSet{true, true, true};
  Networks n = Networks::create(NetworkSpec::of(c), true);
  n.depth->eval();
  n.pose->eval();
  n.flow->eval();
  const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  torch::NoGradGuard no_grad;
  const auto out = compute_losses(n, tgt, srcs, K, stage, c);
  const auto p = predict_pair(n, tgt, srcs.select(1, 1), K, srcs.select(1, 0));
  const auto& trained = out.fwd_full[1][0];
  ASSERT_EQ(p.flow.sizes(), trained.sizes());
  const double scale = trained.abs().max().item<double>();
  EXPECT_GT(scale, 0.1);
  EXPECT_LT((p.flow - trained).abs().max().item<double>(), 1e-4 * scale);
  EXPECT_LT((p.rigid_flow - out.rigid.fwd_flow[1][0]).abs().max().item<double>(), 1e-4 * scale);
  // The residual is not zero: the comparison covers the FlowNet, not only the rigid flow.
  EXPECT_GT((trained - out.rigid.fwd_flow[1][0]).abs().max().item<double>(), 1e-3 * scale);
}

// model.learn_intrinsics: the warp uses the PoseNet's camera. The data's K changes nothing, the
// camera starts at fx = fy = ln 2 W with the principal point centred, and the loss trains the head.
TEST(ComputeLosses, LearnedIntrinsicsReplaceTheDataCamera) {
  torch::manual_seed(13);
  Config c = parse_config("model: {encoder_depth: 18, num_scales: 2, learn_intrinsics: true}\n");
  Networks n = Networks::create(NetworkSpec::of(c), false);
  n.set_trainable(c.stages[0]);
  n.set_modes(c.stages[0]);
  const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
  {
    // Move the pose away from identity so that the camera matters to the warp.
    torch::NoGradGuard no_grad;
    n.pose->pred->bias.fill_(3.0);
  }
  const auto K1 = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  const auto K2 = K1 * torch::tensor({3.f, 3.f, 1.f}).view({1, 3, 1});
  const auto a = compute_losses(n, tgt, srcs, K1, c.stages[0], c);
  const auto b = compute_losses(n, tgt, srcs, K2, c.stages[0], c);
  EXPECT_DOUBLE_EQ(a.losses.total.item<double>(), b.losses.total.item<double>());
  const auto K = n.pose->predict(tgt, {srcs.select(1, 0), srcs.select(1, 1)}).K;
  ASSERT_TRUE(K.defined());
  EXPECT_NEAR(K[0][0][0].item<double>(), std::log(2.0) * 128, 1e-4);
  EXPECT_NEAR(K[0][1][1].item<double>(), std::log(2.0) * 128, 1e-4);
  EXPECT_NEAR(K[0][0][2].item<double>(), 64, 1e-4);
  EXPECT_NEAR(K[0][1][2].item<double>(), 32, 1e-4);
  a.losses.total.backward();
  ASSERT_TRUE(n.pose->intrinsics->weight.grad().defined());
  EXPECT_GT(n.pose->intrinsics->weight.grad().abs().sum().item<double>(), 0);
  // Without learning, the data's camera is used: the two K give different losses.
  Config plain = parse_config("model: {encoder_depth: 18, num_scales: 2}\n");
  torch::manual_seed(13);
  Networks m = Networks::create(NetworkSpec::of(plain), false);
  m.set_modes(plain.stages[0]);
  {
    torch::NoGradGuard no_grad;
    m.pose->pred->bias.fill_(3.0);
  }
  torch::NoGradGuard no_grad;
  EXPECT_NE(compute_losses(m, tgt, srcs, K1, plain.stages[0], plain).losses.total.item<double>(),
            compute_losses(m, tgt, srcs, K2, plain.stages[0], plain).losses.total.item<double>());
}

// stages[].freeze_batch_norm (geo_infer --refine): the weights train while every BatchNorm
// normalises with, and keeps, its running statistics; without it a step moves them.
TEST(ComputeLosses, FrozenBatchNormKeepsItsRunningStatistics) {
  auto running = [](const Networks& n) {
    std::vector<torch::Tensor> out;
    for (const torch::nn::Module* net :
         {static_cast<const torch::nn::Module*>(n.depth.get()), static_cast<const torch::nn::Module*>(n.pose.get())})
      for (const auto& m : net->modules())
        if (const auto* bn = m->as<SyncBatchNorm2d>()) out.push_back(bn->running_mean.clone());
    return out;
  };
  const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  for (const bool frozen : {true, false}) {
    Config c = parse_config(std::string("model: {encoder_depth: 18, num_scales: 2}\nstages: [{freeze_batch_norm: ") +
                            (frozen ? "true" : "false") + "}]\n");
    torch::manual_seed(5);
    Networks n = Networks::create(NetworkSpec::of(c), false);
    n.set_trainable(c.stages[0]);
    n.set_modes(c.stages[0]);
    EXPECT_TRUE(n.depth->is_training());
    const auto before = running(n);
    ASSERT_GT(before.size(), 20u);
    compute_losses(n, tgt, srcs, K, c.stages[0], c).losses.total.backward();
    const auto after = running(n);
    size_t moved = 0;
    for (size_t i = 0; i < before.size(); ++i) moved += torch::equal(before[i], after[i]) ? 0 : 1;
    EXPECT_EQ(moved, frozen ? 0u : before.size()) << (frozen ? "frozen" : "training");
    ASSERT_TRUE(n.depth->parameters().front().grad().defined());  // the weights train either way
    EXPECT_GT(n.depth->parameters().front().grad().abs().sum().item<double>(), 0);
  }
}

// loss.flow_input_gradient (GeoNet's graph): in a stage that trains depth and pose with the flow,
// L_fr reaches the DepthNet and PoseNet through the FlowNet's input too. The FlowNet's own gradients
// are the same either way (bit for bit: the same forward values and the same gradient from the loss);
// the DepthNet's and PoseNet's differ; in a flow-only stage the setting changes nothing.
TEST(ComputeLosses, FlowInputGradientReachesDepthAndPoseOnlyInAJointStage) {
  const auto tgt = torch::rand({2, 3, 64, 128}), srcs = torch::rand({2, 2, 3, 64, 128});
  const auto K = torch::tensor({60.f, 0.f, 64.f, 0.f, 60.f, 32.f, 0.f, 0.f, 1.f}).view({1, 3, 3}).repeat({2, 1, 1});
  auto gradients = [&](bool keep, bool joint) {
    Config c = parse_config(std::string("model: {encoder_depth: 18, num_scales: 2}\nloss: {flow_input_gradient: ") +
                            (keep ? "true" : "false") +
                            "}\nstages: [{weights: {rigid: 0, disp_smooth: 0, flow: 1, flow_smooth: 0, "
                            "flow_consistency: 0}}]\n");
    c.stages[0].train = NetworkSet{joint, joint, true};
    torch::manual_seed(5);
    Networks n = Networks::create(NetworkSpec::of(c), true);
    n.set_trainable(c.stages[0]);
    n.set_modes(c.stages[0]);
    compute_losses(n, tgt, srcs, K, c.stages[0], c).losses.total.backward();
    std::map<std::string, std::vector<torch::Tensor>> g;
    for (auto [name, net] : std::vector<std::pair<std::string, torch::nn::Module*>>{
             {"depth", n.depth.get()}, {"pose", n.pose.get()}, {"flow", n.flow.get()}})
      for (const auto& p : net->parameters())
        g[name].push_back(p.grad().defined() ? p.grad().clone() : torch::zeros_like(p));
    return g;
  };
  auto same = [](const std::vector<torch::Tensor>& a, const std::vector<torch::Tensor>& b) {
    for (size_t i = 0; i < a.size(); ++i)
      if (!torch::equal(a[i], b[i])) return false;
    return true;
  };
  auto norm = [](const std::vector<torch::Tensor>& a) {
    double s = 0;
    for (const auto& t : a) s += t.square().sum().item<double>();
    return std::sqrt(s);
  };
  auto distance = [](const std::vector<torch::Tensor>& a, const std::vector<torch::Tensor>& b) {
    double s = 0;
    for (size_t i = 0; i < a.size(); ++i) s += (a[i] - b[i]).square().sum().item<double>();
    return std::sqrt(s);
  };
  const auto kept = gradients(true, true), cut = gradients(false, true);
  EXPECT_TRUE(same(kept.at("flow"), cut.at("flow")));
  for (const char* net : {"depth", "pose"}) {
    ASSERT_GT(norm(cut.at(net)), 0) << net << ": L_fr reaches it through the rigid flow either way";
    EXPECT_GT(distance(kept.at(net), cut.at(net)), 1e-3 * norm(cut.at(net))) << net;
  }
  const auto flow_only_kept = gradients(true, false), flow_only_cut = gradients(false, false);
  for (const char* net : {"depth", "pose", "flow"})
    EXPECT_TRUE(same(flow_only_kept.at(net), flow_only_cut.at(net))) << net;
  EXPECT_EQ(norm(flow_only_kept.at("depth")), 0.0);
}

}  // namespace
}  // namespace geo
