#include "models/fr.h"

#include <gtest/gtest.h>

#include "models/layers.h"

namespace {

TEST(FeatureRefinement, KeepsTheShapeAndGatesLieInZeroOne) {
  torch::manual_seed(20);
  geo::FeatureRefinement fr(geo::FeatureRefinementOptions(32));
  const auto x = torch::randn({2, 32, 7, 9});
  const auto y = fr(x);
  EXPECT_EQ(y.sizes(), x.sizes());
  const auto ac = fr->channel_gate(x);
  EXPECT_EQ(ac.sizes(), (std::vector<int64_t>{2, 32, 1, 1}));
  EXPECT_GT(ac.min().item<float>(), 0.f);
  EXPECT_LT(ac.max().item<float>(), 1.f);
  const auto f1 = x * ac;
  const auto as = fr->spatial_gate(f1);
  EXPECT_EQ(as.sizes(), (std::vector<int64_t>{2, 1, 7, 9}));
  EXPECT_GT(as.min().item<float>(), 0.f);
  EXPECT_LT(as.max().item<float>(), 1.f);
  // forward is exactly F * a_c * a_s.
  EXPECT_TRUE(torch::allclose(y, f1 * as));
}

TEST(FeatureRefinement, ParameterCountIsSharedMlpPlusSpatialConv) {
  // C = 64, r = 16: MLP 64 -> 4 -> 64 without bias (2 * 64 * 4) + 7x7 conv over 2 channels (98).
  EXPECT_EQ(geo::count_parameters(*geo::FeatureRefinement(geo::FeatureRefinementOptions(64))),
            2 * 64 * 4 + 98);
  // C = 8 < r: the hidden width is clamped to 1.
  EXPECT_EQ(geo::count_parameters(*geo::FeatureRefinement(geo::FeatureRefinementOptions(8))),
            2 * 8 * 1 + 98);
}

// The fused pooling against amax/mean in value and gradient, with ties (ReLU zeros, repeated
// integers) where the max's gradient is shared evenly, and with only one of the two outputs used.
TEST(FeatureRefinement, FusedMaxMeanPoolingMatchesAmaxAndMean) {
  torch::manual_seed(5);
  const auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  for (auto shape : std::vector<std::vector<int64_t>>{{2, 3, 4, 5}, {1, 1, 1, 1}, {2, 16, 3, 1}}) {
    auto x = torch::relu(torch::randint(-3, 4, shape, opts)).requires_grad_();  // many ties
    for (bool channels : {true, false}) {
      const auto got = channels ? geo::max_mean_over_channels(x) : geo::max_mean_over_space(x);
      const auto ref = channels ? std::make_pair(x.amax(1, true), x.mean(1, true))
                                : std::make_pair(x.amax({2, 3}, true), x.mean({2, 3}, true));
      ASSERT_EQ(got.first.sizes(), ref.first.sizes());
      EXPECT_TRUE(torch::equal(got.first, ref.first));
      EXPECT_LT((got.second - ref.second).abs().max().item<double>(), 1e-12);
      const auto gm = torch::randn_like(ref.first), ga = torch::randn_like(ref.second);
      const auto want = torch::autograd::grad({ref.first, ref.second}, {x}, {gm, ga}, /*retain_graph=*/true)[0];
      const auto have = torch::autograd::grad({got.first, got.second}, {x}, {gm, ga}, /*retain_graph=*/true)[0];
      EXPECT_LT((want - have).abs().max().item<double>(), 1e-12) << (channels ? "channels" : "space");
      const auto max_only = torch::autograd::grad({got.first}, {x}, {gm})[0];
      EXPECT_LT((max_only - torch::autograd::grad({ref.first}, {x}, {gm})[0]).abs().max().item<double>(), 1e-12);
    }
  }
  // Hand-computed tie: channels (2, 2, 1) at one pixel -> max 2, gradient 1 shared as (0.5, 0.5, 0).
  const auto t = torch::tensor({2., 2., 1.}, opts).view({1, 3, 1, 1}).requires_grad_();
  const auto g = torch::autograd::grad({geo::max_mean_over_channels(t).first}, {t})[0];
  EXPECT_TRUE(torch::equal(g.view({3}), torch::tensor({0.5, 0.5, 0.0}, opts)));
}

TEST(FeatureRefinement, WrongChannelCountThrows) {
  geo::FeatureRefinement fr(geo::FeatureRefinementOptions(16));
  EXPECT_THROW(fr(torch::zeros({1, 8, 4, 4})), c10::Error);
}

}  // namespace
