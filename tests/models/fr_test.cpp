#include "models/fr.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

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
}

// CBAM (Woo et al. 2018) written out from its definition with the module's weights, element by
// element in float64: a_c = sigmoid(W2 relu(W1 avg) + W2 relu(W1 max)) over each channel's pixels,
// F1 = F a_c, a_s = sigmoid(7x7 conv, zero padding 3, of [max over channels, mean over channels] of
// F1), output F1 a_s. Fails if the gates are swapped, a pooling is dropped or the order changes.
TEST(FeatureRefinement, ForwardIsCbamWrittenOut) {
  torch::manual_seed(21);
  const int64_t B = 2, C = 20, H = 5, W = 6, K = 7;
  geo::FeatureRefinement fr{geo::FeatureRefinementOptions(C)};  // hidden width 20 / 16 -> 1
  fr->to(torch::kFloat64);
  const auto x = torch::randn({B, C, H, W}, torch::kFloat64);
  const auto y = fr(x);
  const auto w1 = fr->mlp_in->weight.view({-1, C}), w2 = fr->mlp_out->weight.view({C, -1});
  const auto ws = fr->spatial->weight;  // [1,2,7,7]
  ASSERT_EQ(w1.size(0), 1);
  auto sigmoid = [](double v) { return 1 / (1 + std::exp(-v)); };
  for (int64_t b = 0; b < B; ++b) {
    std::vector<double> avg(C, 0.0), mx(C, -1e300);
    for (int64_t c = 0; c < C; ++c)
      for (int64_t i = 0; i < H; ++i)
        for (int64_t j = 0; j < W; ++j) {
          const double v = x[b][c][i][j].item<double>();
          avg[c] += v / (H * W);
          mx[c] = std::max(mx[c], v);
        }
    double h_avg = 0, h_max = 0;  // the hidden unit
    for (int64_t c = 0; c < C; ++c) {
      h_avg += w1[0][c].item<double>() * avg[c];
      h_max += w1[0][c].item<double>() * mx[c];
    }
    h_avg = std::max(h_avg, 0.0);
    h_max = std::max(h_max, 0.0);
    std::vector<double> f1(C * H * W), pmax(H * W, -1e300), pmean(H * W, 0.0);
    for (int64_t c = 0; c < C; ++c) {
      const double ac = sigmoid(w2[c][0].item<double>() * h_avg + w2[c][0].item<double>() * h_max);
      for (int64_t p = 0; p < H * W; ++p) {
        const double v = x[b][c][p / W][p % W].item<double>() * ac;
        f1[c * H * W + p] = v;
        pmax[p] = std::max(pmax[p], v);
        pmean[p] += v / C;
      }
    }
    for (int64_t i = 0; i < H; ++i)
      for (int64_t j = 0; j < W; ++j) {
        double a = 0;
        for (int64_t u = 0; u < K; ++u)
          for (int64_t v = 0; v < K; ++v) {
            const int64_t r = i + u - K / 2, q = j + v - K / 2;
            if (r < 0 || r >= H || q < 0 || q >= W) continue;  // zero padding
            a += ws[0][0][u][v].item<double>() * pmax[r * W + q] + ws[0][1][u][v].item<double>() * pmean[r * W + q];
          }
        for (int64_t c = 0; c < C; ++c)
          EXPECT_NEAR(y[b][c][i][j].item<double>(), f1[c * H * W + i * W + j] * sigmoid(a), 1e-12)
              << "b " << b << " c " << c << " at " << i << "," << j;
      }
  }
}

TEST(FeatureRefinement, ParameterCountIsSharedMlpPlusSpatialConv) {
  // C = 64, r = 16: MLP 64 -> 4 -> 64 without bias (2 * 64 * 4) + 7x7 conv over 2 channels (98).
  EXPECT_EQ(geo::count_parameters(*geo::FeatureRefinement(geo::FeatureRefinementOptions(64))), 2 * 64 * 4 + 98);
  // C = 8 < r: the hidden width is clamped to 1.
  EXPECT_EQ(geo::count_parameters(*geo::FeatureRefinement(geo::FeatureRefinementOptions(8))), 2 * 8 * 1 + 98);
}

// The fused pooling against amax/mean in value and gradient, with ties (ReLU zeros, repeated
// integers) where the max's gradient is shared evenly, and with only one of the two outputs used.
TEST(FeatureRefinement, FusedMaxMeanPoolingMatchesAmaxAndMean) {
  torch::manual_seed(5);
  const auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  // Also in channels-last order (inference's activations), pooled where they lie.
  for (auto shape : std::vector<std::vector<int64_t>>{{2, 3, 4, 5}, {1, 1, 1, 1}, {2, 16, 3, 1}})
    for (bool channels_last : {false, true}) {
      auto x = torch::relu(torch::randint(-3, 4, shape, opts));  // many ties
      if (channels_last) x = x.contiguous(at::MemoryFormat::ChannelsLast);
      x.requires_grad_();
      SCOPED_TRACE(channels_last ? "channels-last" : "dense");
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
