// Shapes, ranges, gradients, parameter counts and state round trips of DepthNet, PoseNet, FlowNet.
#include <gtest/gtest.h>

#include <filesystem>
#include <functional>
#include <map>

#include "core/state_io.h"
#include "models/depth_net.h"
#include "models/flow_net.h"
#include "models/pose_net.h"

namespace {

using Sizes = std::vector<int64_t>;

geo::DepthNetOptions small(bool fr = true) {
  geo::DepthNetOptions o;
  o.encoder_depth = 18;
  o.use_fr = fr;
  return o;
}

int64_t fr_parameters(const torch::nn::Module& m) {
  int64_t n = 0;
  for (const auto& p : m.named_parameters())
    if (p.key().find("refined") != std::string::npos) n += p.value().numel();
  return n;
}

TEST(DepthNet, ResNet50ShapesAndRangeAt128x416) {
  torch::manual_seed(21);
  geo::DepthNet net;  // paper defaults: ResNet-50 with FR
  net->eval();
  torch::NoGradGuard no_grad;
  const auto out = net(torch::rand({1, 3, 128, 416}));
  ASSERT_EQ(out.disp.size(), 4u);
  for (int s = 0; s < 4; ++s) {
    EXPECT_EQ(out.disp[s].sizes(), (Sizes{1, 1, 128 >> s, 416 >> s})) << "scale " << s;
    EXPECT_GT(out.disp[s].min().item<float>(), 0.01f);
    EXPECT_LT(out.disp[s].max().item<float>(), 5.01f);
  }
}

TEST(DepthNet, OddSizesWork) {
  torch::manual_seed(22);
  geo::DepthNet net(small());
  net->eval();
  torch::NoGradGuard no_grad;
  const auto out = net(torch::rand({1, 3, 75, 250}));
  EXPECT_EQ(out.disp[0].sizes(), (Sizes{1, 1, 75, 250}));
  EXPECT_EQ(out.disp[1].sizes(), (Sizes{1, 1, 38, 125}));  // the encoder's ceil(H/2) scale
  EXPECT_GT(out.disp[0].min().item<float>(), 0.01f);
  EXPECT_LT(out.disp[0].max().item<float>(), 5.01f);
  EXPECT_THROW(net(torch::rand({1, 4, 64, 64})), c10::Error);
}

TEST(DepthNet, FrOffHasExactlyTheFrParametersFewer) {
  const geo::DepthNet on, off([] {
    geo::DepthNetOptions o;
    o.use_fr = false;
    return o;
  }());
  // Hand count: FR(C) = 2 C (C/16) + 98 for C = 256, 512, 1024, 2048 (encoder) and
  // 512, 256, 128, 64, 32, 16 (decoder; C/16 clamped to >= 1): 696712 + 44268.
  EXPECT_EQ(geo::count_parameters(*on) - geo::count_parameters(*off), 740980);
  EXPECT_EQ(fr_parameters(*on), 740980);
  EXPECT_EQ(fr_parameters(*off), 0);
}

TEST(PoseNet, ShapesForThreeAndFiveFrameSnippets) {
  torch::manual_seed(23);
  geo::PoseNet net3;
  const auto t = torch::rand({2, 3, 128, 416});
  const auto p = net3->forward(t, {torch::rand({2, 3, 128, 416}), torch::rand({2, 3, 128, 416})});
  EXPECT_EQ(p.sizes(), (Sizes{2, 2, 6}));
  geo::PoseNetOptions o;
  o.seq_length = 5;
  geo::PoseNet net5(o);
  net5->eval();
  const auto odd = torch::rand({1, 3, 75, 250});
  EXPECT_EQ(net5->forward(odd, {odd, odd, odd, odd}).sizes(), (Sizes{1, 4, 6}));
  EXPECT_THROW(net5->forward(odd, {odd}), c10::Error);
}

TEST(FlowNet, ResidualFlowShapesAt128x416AndOddSize) {
  torch::manual_seed(24);
  geo::FlowNet net;  // paper defaults
  net->eval();
  torch::NoGradGuard no_grad;
  const auto img = torch::rand({1, 3, 128, 416});
  const auto in = geo::flow_net_input(img, img, img, torch::zeros({1, 2, 128, 416}), torch::zeros({1, 1, 128, 416}));
  EXPECT_EQ(in.sizes(), (Sizes{1, 12, 128, 416}));
  const auto out = net(in);
  ASSERT_EQ(out.flow.size(), 4u);
  for (int s = 0; s < 4; ++s) EXPECT_EQ(out.flow[s].sizes(), (Sizes{1, 2, 128 >> s, 416 >> s}));
  geo::FlowNetOptions o;
  o.backbone = small();
  geo::FlowNet small_net(o);
  small_net->eval();
  EXPECT_EQ(small_net(torch::rand({1, 12, 75, 250})).flow[0].sizes(), (Sizes{1, 2, 75, 250}));
  EXPECT_THROW(geo::flow_net_input(img, img, img, torch::zeros({1, 3, 128, 416}), torch::zeros({1, 1, 128, 416})),
               c10::Error);
}

// Every parameter gets a finite, non-zero gradient from a loss on the outputs, with one exception
// that depends on the initial weights, not on the wiring: an FR block's shared MLP (mlp_in, mlp_out)
// gets an exactly-zero gradient when every one of its hidden ReLU units is inactive for the whole
// batch (its inputs, pooled post-ReLU features, are non-negative and it has no bias, so a few
// random rows of mlp_in can all point away from them). Such a block must still be wired in: its
// MLP's gradient is defined (autograd reached it) and its spatial convolution's is non-zero. So
// any seed passes, and a block left out of the graph still fails.
void expect_all_gradients(torch::nn::Module& net, const std::function<torch::Tensor()>& loss_of) {
  net.train();
  loss_of().backward();
  std::map<std::string, torch::Tensor> grads;
  for (const auto& p : net.named_parameters()) grads[p.key()] = p.value().grad();
  std::vector<std::string> without;
  for (const auto& [name, g] : grads) {
    if (!g.defined() || !torch::isfinite(g).all().item<bool>()) {
      without.push_back(name + (g.defined() ? " (not finite)" : " (none)"));
      continue;
    }
    if (g.abs().sum().item<double>() != 0) continue;
    const auto mlp = name.find("mlp_");
    if (mlp != std::string::npos) {
      const auto spatial = grads.find(name.substr(0, mlp) + "spatial.weight");
      if (spatial != grads.end() && spatial->second.defined() && spatial->second.abs().sum().item<double>() > 0)
        continue;
    }
    without.push_back(name + " (zero)");
  }
  EXPECT_TRUE(without.empty()) << "no gradient: " << without.size() << " parameters, first "
                               << (without.empty() ? "" : without[0]);
}

// A loss that reaches every output element with a random weight (no symmetric cancellation).
torch::Tensor random_projection(const std::vector<torch::Tensor>& outputs) {
  torch::Tensor loss = torch::zeros({});
  for (const auto& o : outputs) loss = loss + (o * torch::randn_like(o)).sum();
  return loss;
}

TEST(Networks, FlowZeroInitStartsFromTheRigidFlow) {
  // model.flow_zero_init: every scale's residual is exactly 0 before training (GeoNet's Xavier
  // init gives a random one), and the zeroed prediction convs still get a gradient.
  torch::manual_seed(5);
  geo::FlowNetOptions o;
  o.backbone = small();
  o.zero_init_residual = true;
  geo::FlowNet zero(o);
  o.zero_init_residual = false;
  geo::FlowNet xavier(o);
  const auto img = torch::rand({2, 3, 32, 64});
  const auto in = geo::flow_net_input(img, img.flip(3), img, torch::ones({2, 2, 32, 64}), torch::ones({2, 1, 32, 64}));
  const auto out = zero(in);
  for (const auto& f : out.flow) EXPECT_EQ(f.abs().max().item<double>(), 0.0);
  EXPECT_GT(xavier(in).flow[0].abs().max().item<double>(), 0.1);  // pixels
  (out.flow[0] * torch::rand_like(out.flow[0])).sum().backward();
  EXPECT_GT(zero->net->pred.back()->weight.grad().abs().sum().item<double>(), 0.0);
}

TEST(Networks, EveryParameterReceivesAGradient) {
  torch::manual_seed(25);  // any seed (25 leaves refined7's 8-wide MLP all-inactive at init: see expect_all_gradients)
  geo::DepthNetOptions d50;  // ResNet-50 with FR, small input
  geo::DepthNet depth(d50);
  expect_all_gradients(*depth, [&] { return random_projection(depth(torch::rand({2, 3, 64, 64})).disp); });
  geo::PoseNet pose;
  expect_all_gradients(*pose, [&] {
    return random_projection(
        {pose->forward(torch::rand({2, 3, 64, 64}), {torch::rand({2, 3, 64, 64}), torch::rand({2, 3, 64, 64})})});
  });
  geo::FlowNetOptions fo;
  fo.backbone = small();
  geo::FlowNet flow(fo);
  expect_all_gradients(*flow, [&] { return random_projection(flow(torch::randn({2, 12, 64, 64})).flow); });
}

TEST(Networks, SaveLoadGivesIdenticalOutputsAndMismatchListsKeys) {
  torch::manual_seed(26);
  const auto dir = std::filesystem::temp_directory_path();
  const auto path = (dir / "geo_depth_state.pt").string();
  geo::DepthNet a(small()), b(small());
  a->eval();
  b->eval();
  geo::save_state(*a, path);
  geo::load_state(*b, path);
  const auto x = torch::rand({1, 3, 64, 128});
  torch::NoGradGuard no_grad;
  const auto ya = a(x), yb = b(x);
  for (int s = 0; s < 4; ++s) EXPECT_TRUE(torch::equal(ya.disp[s], yb.disp[s]));
  geo::DepthNet no_fr(small(false));
  try {
    geo::load_state(*no_fr, path);
    FAIL() << "expected a mismatch error";
  } catch (const std::runtime_error& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("unexpected keys: net.encoder.refined1"), std::string::npos) << msg;
    EXPECT_NE(msg.find("refined"), std::string::npos) << msg;
  }
  std::filesystem::remove(path);
}

}  // namespace
