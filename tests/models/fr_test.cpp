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

TEST(FeatureRefinement, WrongChannelCountThrows) {
  geo::FeatureRefinement fr(geo::FeatureRefinementOptions(16));
  EXPECT_THROW(fr(torch::zeros({1, 8, 4, 4})), c10::Error);
}

}  // namespace
