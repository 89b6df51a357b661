#include "losses/depth_anchor.h"

#include <gtest/gtest.h>

#include <cmath>

namespace {

torch::Tensor disparity(std::initializer_list<double> depths) {
  return torch::tensor(std::vector<double>(depths), torch::kFloat64).reciprocal().view({1, 1, 1, -1});
}

TEST(DepthAnchor, TheTeachersOwnDepthAtAnyScaleCostsNothing) {
  const auto t = disparity({1, 2, 4, 8});
  EXPECT_EQ(geo::depth_anchor(t, t).item<double>(), 0.0);
  EXPECT_NEAR(geo::depth_anchor(t * 5.0, t).item<double>(), 0.0, 1e-15);  // depth / 5: the same shape
}

TEST(DepthAnchor, IsTheMeanLogRatioOfDepthsEachOverItsMean) {
  // Depths (1, 2) against a flat teacher (1, 1): mean 1.5, |log(1/1.5)| and |log(2/1.5)|,
  // whose mean is (log 1.5 + log(4/3)) / 2 = log(2) / 2.
  EXPECT_NEAR(geo::depth_anchor(disparity({1, 2}), disparity({1, 1})).item<double>(), std::log(2.0) / 2, 1e-15);
  // Each image of a batch has its own mean: the second image (3, 3) against (1, 1) costs nothing.
  const auto d = torch::cat({disparity({1, 2}), disparity({3, 3})}, 0);
  const auto t = torch::cat({disparity({1, 1}), disparity({1, 1})}, 0);
  EXPECT_NEAR(geo::depth_anchor(d, t).item<double>(), std::log(2.0) / 4, 1e-15);
}

TEST(DepthAnchor, ItsGradientPullsTowardsTheTeacherAndNeverIntoIt) {
  // Depths (1, 2) against (1, 1): the far pixel is too far (its disparity must grow), the near one
  // too near (its disparity must shrink); the teacher gets no gradient.
  auto d = disparity({1, 2}).requires_grad_(true);
  auto t = disparity({1, 1}).requires_grad_(true);
  geo::depth_anchor(d, t).backward();
  // By hand: L = (-x0 + x1) / 2, x_i = log(z_i) - log(mean z); dL/dz0 = -1/2, dL/dz1 = 1/4, and
  // dz/d disp = -z^2: dL/d disp0 = 1/2 (positive), dL/d disp1 = -1 (negative).
  EXPECT_NEAR(d.grad()[0][0][0][0].item<double>(), 0.5, 1e-12);
  EXPECT_NEAR(d.grad()[0][0][0][1].item<double>(), -1.0, 1e-12);
  EXPECT_FALSE(t.grad().defined());
}

TEST(DepthAnchor, RefusesMismatchedShapesNamingThem) {
  try {
    geo::depth_anchor(torch::ones({1, 1, 2, 3}), torch::ones({1, 1, 3, 2}));
    FAIL() << "no error";
  } catch (const c10::Error& e) {
    EXPECT_NE(std::string(e.what()).find("teacher_disp"), std::string::npos) << e.what();
  }
}

}  // namespace
