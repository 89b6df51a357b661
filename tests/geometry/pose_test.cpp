#include "geometry/pose.h"

#include <gtest/gtest.h>

#include <cmath>

namespace {

void expect_close(const torch::Tensor& a, const torch::Tensor& b, double tol) {
  ASSERT_EQ(a.sizes(), b.sizes());
  EXPECT_LE((a - b).abs().max().item<double>(), tol) << a << "\nvs\n" << b;
}

torch::Tensor vec(std::initializer_list<double> v) {
  return torch::tensor(std::vector<double>(v), torch::kFloat64).view({1, -1});
}

TEST(Pose, RoundTripRandomZeroTinyAndLargeAngles) {
  torch::manual_seed(3);
  auto random = torch::rand({16, 6}, torch::kFloat64) * 2 - 1;  // angles within (-1, 1) rad
  random.narrow(1, 0, 3).mul_(10);
  const double big = M_PI - 1e-3;
  const auto cases = torch::cat({random, vec({0, 0, 0, 0, 0, 0}), vec({1e-8, -1e-8, 1e-8, 1e-8, -1e-8, 1e-8}),
                                 vec({1, 2, 3, big, 1.5, -big}), vec({0, 0, 0, -big, -1.5, big})});
  const auto back = geo::matrix_to_pose_vec(geo::pose_vec_to_matrix(cases));
  expect_close(back, cases, 1e-9);
  // Tiny angles keep their relative precision.
  EXPECT_NEAR(back[17][3].item<double>(), 1e-8, 1e-20);
}

TEST(Pose, RotationOrderIsRxRyRz) {
  // rx = 90 deg, ry = 90 deg, rz = 0: R = Rx Ry = [[0,0,1],[1,0,0],[0,1,0]] (hand-computed).
  // The other order (Ry Rx) would give [[0,1,0],[0,0,-1],[-1,0,0]].
  const auto T = geo::pose_vec_to_matrix(vec({0, 0, 0, M_PI / 2, M_PI / 2, 0}));
  const auto expected = torch::tensor({0., 0., 1., 1., 0., 0., 0., 1., 0.}, torch::kFloat64).view({3, 3});
  expect_close(T[0].narrow(0, 0, 3).narrow(1, 0, 3), expected, 1e-12);
  // rz = 90 deg alone rotates x onto y: R e_x = e_y.
  const auto Rz = geo::pose_vec_to_matrix(vec({0, 0, 0, 0, 0, M_PI / 2}));
  expect_close(Rz[0].narrow(0, 0, 3).select(1, 0), torch::tensor({0., 1., 0.}, torch::kFloat64), 1e-12);
  // Translation sits in the last column; bottom row is (0,0,0,1).
  const auto Tt = geo::pose_vec_to_matrix(vec({1, 2, 3, 0.1, 0.2, 0.3}));
  expect_close(Tt[0].narrow(0, 0, 3).select(1, 3), torch::tensor({1., 2., 3.}, torch::kFloat64), 0);
  expect_close(Tt[0][3], torch::tensor({0., 0., 0., 1.}, torch::kFloat64), 0);
}

TEST(Pose, AnglesAreClippedToPlusMinusPiAsGeoNet) {
  // rx = 4 rad is clipped to pi: the rotation of pi (R = diag(1, -1, -1)), not of 4 rad; the
  // clipped angle passes no gradient.
  auto v = vec({0, 0, 0, 4.0, 0, 0}).requires_grad_(true);
  const auto T = geo::pose_vec_to_matrix(v);
  expect_close(T[0].narrow(0, 0, 3).narrow(1, 0, 3), torch::diag(torch::tensor({1., -1., -1.}, torch::kFloat64)),
               1e-12);
  T.sum().backward();
  EXPECT_EQ(v.grad()[0][3].item<double>(), 0.0);
  expect_close(geo::pose_vec_to_matrix(vec({0, 0, 0, 0, -7.0, 0})),
               geo::pose_vec_to_matrix(vec({0, 0, 0, 0, -M_PI, 0})), 0);
}

TEST(Pose, InverseAndComposition) {
  torch::manual_seed(4);
  const auto a = geo::pose_vec_to_matrix(torch::rand({5, 6}, torch::kFloat64));
  const auto b = geo::pose_vec_to_matrix(torch::rand({5, 6}, torch::kFloat64));
  const auto eye = torch::eye(4, torch::kFloat64).expand({5, 4, 4});
  expect_close(geo::compose(a, geo::inverse_transform(a)), eye, 1e-12);
  expect_close(geo::compose(geo::inverse_transform(a), a), eye, 1e-12);
  // (a b)^-1 = b^-1 a^-1
  expect_close(geo::inverse_transform(geo::compose(a, b)),
               geo::compose(geo::inverse_transform(b), geo::inverse_transform(a)), 1e-12);
}

TEST(Pose, AxisAngleMatchesEulerForSingleAxisRotations) {
  for (int axis = 0; axis < 3; ++axis) {
    auto aa = torch::zeros({1, 3}, torch::kFloat64);
    aa[0][axis] = 0.7;
    auto euler = torch::zeros({1, 6}, torch::kFloat64);
    euler[0][3 + axis] = 0.7;
    euler.narrow(1, 0, 3).copy_(torch::tensor({0.5, -1., 2.}, torch::kFloat64).view({1, 3}));
    expect_close(geo::axisangle_to_matrix(aa, euler.narrow(1, 0, 3)), geo::pose_vec_to_matrix(euler), 1e-12);
  }
  // Zero axis-angle is the identity rotation.
  expect_close(geo::axisangle_to_matrix(torch::zeros({1, 3}, torch::kFloat64), torch::zeros({1, 3}, torch::kFloat64)),
               torch::eye(4, torch::kFloat64).unsqueeze(0), 0);
}

TEST(Pose, MalformedShapesNameTheArgument) {
  try {
    geo::pose_vec_to_matrix(torch::zeros({2, 5}));
    FAIL();
  } catch (const c10::Error& e) {
    const std::string msg = e.what_without_backtrace();
    EXPECT_NE(msg.find("pose_vec must have shape [-1, 6]"), std::string::npos) << msg;
    EXPECT_NE(msg.find("got [2, 5]"), std::string::npos) << msg;
  }
  EXPECT_THROW(geo::inverse_transform(torch::zeros({4, 4})), c10::Error);
}

}  // namespace
