#include "losses/photometric.h"

#include <gtest/gtest.h>

namespace {

constexpr double C1 = 1e-4, C2 = 9e-4;

TEST(Ssim, OfAnImageWithItselfIsOneAndErrorZero) {
  torch::manual_seed(10);
  const auto x = torch::rand({2, 3, 8, 8}, torch::kFloat64);
  EXPECT_LT((geo::ssim(x, x) - 1).abs().max().item<double>(), 1e-12);
  EXPECT_LT(geo::photometric_error(x, x, 0.85).abs().max().item<double>(), 1e-12);
}

TEST(Ssim, HandComputed4x4Case) {
  // x: constant 0.5; y: 4x4 checkerboard (0/1). Every 3x3 window inside the image holds 4 or 5
  // ones out of 9. sigma_x = sigma_xy = 0, so SSIM = (2 mx my + C1) C2 / ((mx^2 + my^2 + C1)(vy + C2)).
  const auto x = torch::full({1, 1, 4, 4}, 0.5, torch::kFloat64);
  auto y = torch::zeros({1, 1, 4, 4}, torch::kFloat64);
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) y[0][0][r][c] = (r + c) % 2;
  const auto s = geo::ssim(x, y);
  auto expected = [](double my, double ey2) {
    const double vy = ey2 - my * my;
    return (2 * 0.5 * my + C1) * C2 / ((0.25 + my * my + C1) * (vy + C2));
  };
  // Pixel (1,1): window rows/cols 0..2 holds 4 ones: my = 4/9, E[y^2] = 4/9.
  EXPECT_NEAR(s[0][0][1][1].item<double>(), expected(4.0 / 9, 4.0 / 9), 1e-12);
  // Pixel (1,2): 5 ones.
  EXPECT_NEAR(s[0][0][1][2].item<double>(), expected(5.0 / 9, 5.0 / 9), 1e-12);
  // Corner (0,0): TF 'SAME' pooling averages the 4 pixels inside: y = 0,1,1,0 -> my = 1/2.
  EXPECT_NEAR(s[0][0][0][0].item<double>(), expected(0.5, 0.5), 1e-12);
  // Edge (0,1): 6 pixels inside (rows 0-1, cols 0-2): 1,0,1 / 0,1,0 -> 3 ones of 6.
  EXPECT_NEAR(s[0][0][0][1].item<double>(), expected(0.5, 0.5), 1e-12);
  // Photometric error at (1,1): 0.85 * (1 - s)/2 + 0.15 * |0.5 - 0| (y(1,1) = 0).
  const auto e = geo::photometric_error(x, y, 0.85);
  EXPECT_NEAR(e[0][0][1][1].item<double>(), 0.85 * (1 - expected(4.0 / 9, 4.0 / 9)) / 2 + 0.15 * 0.5, 1e-12);
}

TEST(Ssim, ConstantImagesClosedForm) {
  const auto x = torch::full({1, 1, 4, 4}, 0.5, torch::kFloat64);
  const auto y = torch::full({1, 1, 4, 4}, 0.25, torch::kFloat64);
  const double want = (2 * 0.5 * 0.25 + C1) / (0.25 + 0.0625 + C1);
  EXPECT_LT((geo::ssim(x, y) - want).abs().max().item<double>(), 1e-12);
}

TEST(Photometric, PyramidIsAreaDownsampling) {
  const auto img = torch::arange(16, torch::kFloat64).view({1, 1, 4, 4});
  const auto p = geo::image_pyramid(img, 3);
  ASSERT_EQ(p.size(), 3u);
  EXPECT_DOUBLE_EQ(p[1][0][0][0][0].item<double>(), (0 + 1 + 4 + 5) / 4.0);
  EXPECT_DOUBLE_EQ(p[2][0][0][0][0].item<double>(), 7.5);
  EXPECT_THROW(geo::image_pyramid(torch::zeros({1, 1, 6, 6}), 3), c10::Error);
}

TEST(Photometric, MaskedMeanAveragesOnlyMaskedPixels) {
  const auto v = torch::tensor({1., 2., 3., 4.}, torch::kFloat64).view({1, 1, 2, 2});
  const auto m = torch::tensor({1., 0., 0., 1.}, torch::kFloat64).view({1, 1, 2, 2});
  EXPECT_DOUBLE_EQ(geo::masked_mean(v, m).item<double>(), 2.5);
  EXPECT_DOUBLE_EQ(geo::masked_mean(v, torch::zeros_like(m)).item<double>(), 0.0);  // empty mask
  EXPECT_THROW(geo::masked_mean(v, torch::ones({1, 2, 2, 2})), c10::Error);
}

TEST(Photometric, ChannelL2NormIsHandComputedWithAGradientThatIsZeroAtZero) {
  // Pixel 0: (3, 4, 0) -> 5, gradient x / 5; pixel 1: (0, 0, 0) -> 0, gradient 0 (not NaN).
  const auto x = torch::tensor({3., 0., 4., 0., 0., 0.}, torch::kFloat64).view({1, 3, 1, 2}).requires_grad_();
  const auto n = geo::channel_l2_norm(x);
  ASSERT_EQ(n.sizes(), (std::vector<int64_t>{1, 1, 1, 2}));
  EXPECT_DOUBLE_EQ(n[0][0][0][0].item<double>(), 5.0);
  EXPECT_DOUBLE_EQ(n[0][0][0][1].item<double>(), 0.0);
  n.sum().backward();
  EXPECT_TRUE(torch::allclose(x.grad(), torch::tensor({0.6, 0., 0.8, 0., 0., 0.}, torch::kFloat64).view({1, 3, 1, 2}),
                              0, 1e-15));
  // Without grad mode: the same values, no graph.
  torch::NoGradGuard no_grad;
  const auto plain = geo::channel_l2_norm(x);
  EXPECT_FALSE(plain.requires_grad());
  EXPECT_TRUE(torch::equal(plain, n.detach()));
}

// The fused CPU kernel against the same error composed of tensor ops (autograd's gradients), at
// sizes with 1-pixel sides and borders, with inputs where the clamp is active and with equal pixels.
TEST(Photometric, FusedKernelMatchesTheComposedOperationsInValueAndGradient) {
  torch::manual_seed(11);
  for (auto hw : std::vector<std::pair<int64_t, int64_t>>{{1, 1}, {1, 5}, {4, 1}, {3, 4}, {7, 9}}) {
    auto x = torch::rand({2, 3, hw.first, hw.second}, torch::kFloat64);
    auto y = torch::rand({2, 3, hw.first, hw.second}, torch::kFloat64);
    y[0][0] = x[0][0];      // equal plane: |x - y| = 0, SSIM = 1
    y[1][2] = 1 - x[1][2];  // anti-correlated plane: negative SSIM
    x.requires_grad_();
    y.requires_grad_();
    for (double alpha : {0.0, 0.85, 1.0}) {
      const auto ref = geo::photometric_error_channels_reference(x, y, alpha);
      const auto got = geo::photometric_error_channels(x, y, alpha);
      ASSERT_EQ(got.sizes(), ref.sizes());
      EXPECT_LT((got - ref).abs().max().item<double>(), 1e-12) << hw.first << "x" << hw.second << " a=" << alpha;
      const auto g = torch::randn_like(ref);
      const auto gr = torch::autograd::grad({ref}, {x, y}, {g});
      const auto gg = torch::autograd::grad({got}, {x, y}, {g});
      for (int i = 0; i < 2; ++i)
        EXPECT_LT((gr[i] - gg[i]).abs().max().item<double>(), 1e-10) << hw.first << "x" << hw.second << " input " << i;
    }
  }
  // float32 agrees with the float64 reference to float rounding; non-contiguous input is accepted.
  const auto x = torch::rand({1, 3, 6, 8}, torch::kFloat64), y = torch::rand({1, 3, 6, 8}, torch::kFloat64);
  const auto xf = x.to(torch::kFloat32).transpose(2, 3).contiguous().transpose(2, 3);
  ASSERT_FALSE(xf.is_contiguous());
  const auto got = geo::photometric_error_channels(xf, y.to(torch::kFloat32), 0.85).to(torch::kFloat64);
  EXPECT_LT((got - geo::photometric_error_channels_reference(x, y, 0.85)).abs().max().item<double>(), 1e-5);
  // Only the input that needs a gradient gets one (the target image does not).
  const auto w = x.clone().requires_grad_();
  const auto gw = torch::autograd::grad({geo::photometric_error_channels(w, y, 0.85).sum()}, {w});
  EXPECT_TRUE(gw[0].defined());
}

TEST(Photometric, MismatchedShapesThrow) {
  EXPECT_THROW(geo::photometric_error_channels(torch::zeros({1, 3, 4, 4}), torch::zeros({1, 3, 4, 5}), 0.85),
               c10::Error);
  EXPECT_THROW(geo::ssim(torch::zeros({1, 3, 4, 4}), torch::zeros({1, 3, 4, 5})), c10::Error);
}

}  // namespace
