#include "engine/motion_model.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include "engine/lg_slam.h"
#include "tests/engine/test_util.h"
#include "tests/shared_data.h"

namespace fastslam::engine {
namespace {

using testing::kVictoriaParkCar;
using testing::matrices_near;
using testing::numeric_jacobian;
using testing::random_heading;

// Every output angle of a state: the heading (component 2) when the state has one.
template <int N>
std::array<bool, N> heading_flags() {
  std::array<bool, N> flags{};
  if constexpr (N >= 3) {
    flags[2] = true;
  }
  return flags;
}

// Checks jacobian_pose and jacobian_control of `model` against central differences at (s, u).
template <class Model>
void expect_jacobians_match(const Model& model, const typename Model::State& s,
                            const typename Model::Control& u, double dt) {
  constexpr int kN = Model::kStateDim;
  constexpr int kC = Model::kControlDim;
  const auto num_pose = numeric_jacobian<kN, kN>(
      [&](const typename Model::State& x) { return model.predict(x, u, dt); }, s,
      heading_flags<kN>());
  const auto num_control = numeric_jacobian<kN, kC>(
      [&](const typename Model::Control& c) { return model.predict(s, c, dt); }, u,
      heading_flags<kN>());
  EXPECT_TRUE(matrices_near(model.jacobian_pose(s, u, dt), num_pose, 1e-7, 1e-6))
      << "pose Jacobian at s = " << s.transpose() << ", u = " << u.transpose();
  EXPECT_TRUE(matrices_near(model.jacobian_control(s, u, dt), num_control, 1e-7, 1e-6))
      << "control Jacobian at s = " << s.transpose() << ", u = " << u.transpose();
}

Pose random_pose(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> pos(-100.0, 100.0);
  return {pos(rng), pos(rng), random_heading(rng)};
}

TEST(BaileyCarModelTest, MatchesTheSimulatorEquations) {
  const BaileyCarModel model(4.0);
  const Pose s(1.0, 2.0, 0.3);
  const Eigen::Vector2d u(3.0, 0.2);
  const double dt = 0.025;
  const Pose next = model.predict(s, u, dt);
  EXPECT_DOUBLE_EQ(next[0], 1.0 + 3.0 * dt * std::cos(0.2 + 0.3));
  EXPECT_DOUBLE_EQ(next[1], 2.0 + 3.0 * dt * std::sin(0.2 + 0.3));
  EXPECT_DOUBLE_EQ(next[2], 0.3 + 3.0 * dt * std::sin(0.2) / 4.0);
}

TEST(BaileyCarModelTest, WrapsTheHeading) {
  const BaileyCarModel model(4.0);
  const Pose next = model.predict(Pose(0.0, 0.0, kPi - 0.001), Eigen::Vector2d(3.0, 0.5), 1.0);
  EXPECT_GT(next[2], -kPi);
  EXPECT_LT(next[2], 0.0);  // crossed the seam
  EXPECT_NEAR(angle_diff(next[2], kPi - 0.001), 3.0 * std::sin(0.5) / 4.0, 1e-12);
}

TEST(BaileyCarModelTest, RejectsABadWheelbase) {
  EXPECT_THROW(BaileyCarModel(0.0), std::invalid_argument);
  EXPECT_THROW(BaileyCarModel(-1.0), std::invalid_argument);
  EXPECT_THROW(BaileyCarModel(std::nan("")), std::invalid_argument);
}

TEST(UnicycleModelTest, MatchesTheEulerStep) {
  const UnicycleModel model;
  const Pose next = model.predict(Pose(1.0, -1.0, 0.5), Eigen::Vector2d(2.0, -0.4), 0.1);
  EXPECT_DOUBLE_EQ(next[0], 1.0 + 2.0 * std::cos(0.5) * 0.1);
  EXPECT_DOUBLE_EQ(next[1], -1.0 + 2.0 * std::sin(0.5) * 0.1);
  EXPECT_DOUBLE_EQ(next[2], 0.5 - 0.04);
}

TEST(AckermannModelTest, MatchesTheReadmeEquations) {
  const AckermannModel model(kVictoriaParkCar);
  const double a = 3.78, b = 0.5, l = 2.83, h = 0.76;
  const Pose s(-67.65, -41.71, 0.66);
  const double ve = 2.5, alpha = -0.12, dt = 0.025;
  const double vc = ve / (1.0 - std::tan(alpha) * h / l);
  const double xd =
      vc * std::cos(s[2]) - (vc / l) * std::tan(alpha) * (a * std::sin(s[2]) + b * std::cos(s[2]));
  const double yd =
      vc * std::sin(s[2]) + (vc / l) * std::tan(alpha) * (a * std::cos(s[2]) - b * std::sin(s[2]));
  const double pd = (vc / l) * std::tan(alpha);
  const Pose next = model.predict(s, Eigen::Vector2d(ve, alpha), dt);
  EXPECT_NEAR(next[0], s[0] + dt * xd, 1e-12);
  EXPECT_NEAR(next[1], s[1] + dt * yd, 1e-12);
  EXPECT_NEAR(next[2], s[2] + dt * pd, 1e-12);
}

TEST(AckermannModelTest, RejectsBadGeometry) {
  EXPECT_THROW(AckermannModel(AckermannGeometry{3.78, 0.5, 0.0, 0.76}), std::invalid_argument);
  EXPECT_THROW(AckermannModel(AckermannGeometry{3.78, 0.5, 2.83, -0.1}), std::invalid_argument);
  EXPECT_THROW(AckermannModel(AckermannGeometry{std::nan(""), 0.5, 2.83, 0.76}),
               std::invalid_argument);
}

TEST(BrownianVelocityModelTest, IsPaperEquations80And81) {
  const BrownianVelocityModel model;
  BrownianVelocityModel::State s;
  s << 1.0, 2.0, 0.4, 3.0, 0.2;
  const double dt = 0.2;
  const double normals[2] = {0.5, -1.0};
  const Eigen::Vector2d sigmas(0.3, 0.05);
  const auto next = model.sample(s, Eigen::Vector2d::Zero(), dt, sigmas, normals);
  const double v = 3.0 + 0.3 * 0.5;
  const double w = 0.2 - 0.05;
  EXPECT_DOUBLE_EQ(next[3], v);
  EXPECT_DOUBLE_EQ(next[4], w);
  EXPECT_DOUBLE_EQ(next[0], 1.0 + v * std::cos(0.4) * dt);
  EXPECT_DOUBLE_EQ(next[1], 2.0 + v * std::sin(0.4) * dt);
  EXPECT_DOUBLE_EQ(next[2], 0.4 + w * dt);
}

// theta += v' kappa' dt, with v' = v + dv and kappa' = kappa + dkappa.
TEST(BrownianCurvatureModelTest, IsTheSpeedAndCurvatureWalk) {
  const BrownianCurvatureModel model;
  BrownianCurvatureModel::State s;
  s << 1.0, 2.0, 0.4, 3.0, 0.2;
  const double dt = 0.2;
  const double normals[2] = {0.5, -1.0};
  const Eigen::Vector2d sigmas(0.3, 0.05);
  const auto next = model.sample(s, Eigen::Vector2d::Zero(), dt, sigmas, normals);
  const double v = 3.0 + 0.3 * 0.5;
  const double kappa = 0.2 - 0.05;
  EXPECT_DOUBLE_EQ(next[3], v);
  EXPECT_DOUBLE_EQ(next[4], kappa);
  EXPECT_DOUBLE_EQ(next[0], 1.0 + v * std::cos(0.4) * dt);
  EXPECT_DOUBLE_EQ(next[1], 2.0 + v * std::sin(0.4) * dt);
  EXPECT_DOUBLE_EQ(next[2], 0.4 + v * kappa * dt);
  // Backwards with a left curvature turns right; the heading is wrapped.
  s << 0.0, 0.0, 3.1, -2.0, -0.5;
  const auto back = model.predict(s, Eigen::Vector2d(0.0, 0.0), 0.5);
  EXPECT_DOUBLE_EQ(back[2], wrap_angle(3.1 + 0.5));
  EXPECT_LT(back[2], 0.0);
}

// A car at rest cannot turn, whatever its curvature (the omega walk turns at v = 0).
TEST(BrownianCurvatureModelTest, DoesNotTurnStandingStill) {
  BrownianCurvatureModel::State s;
  s << 5.0, -3.0, 1.2, 0.0, 0.3;
  const auto still = BrownianCurvatureModel().predict(s, Eigen::Vector2d(0.0, 0.1), 1.0);
  BrownianCurvatureModel::State want = s;
  want[4] += 0.1;
  EXPECT_EQ(still, want);
  const auto spun = BrownianVelocityModel().predict(s, Eigen::Vector2d(0.0, 0.1), 1.0);
  EXPECT_DOUBLE_EQ(spun[2], 1.2 + 0.4);
}

// Jacobians of every model against central differences at many random points, a quarter of
// them with the heading within 1e-3 of +-pi.
TEST(MotionModelJacobianTest, AllModelsMatchCentralDifferences) {
  std::mt19937_64 rng(42);
  std::uniform_real_distribution<double> speed(-5.0, 15.0);
  std::uniform_real_distribution<double> steer(-0.6, 0.6);
  std::uniform_real_distribution<double> rate(-1.0, 1.0);
  std::uniform_real_distribution<double> step(0.01, 0.5);
  const BaileyCarModel bailey(4.0);
  const UnicycleModel unicycle;
  const AckermannModel ackermann(kVictoriaParkCar);
  const BrownianVelocityModel brownian;
  const BrownianCurvatureModel curvature;
  const LinearGaussianMotion linear;
  for (int i = 0; i < 500; ++i) {
    const Pose s = random_pose(rng);
    const double dt = step(rng);
    expect_jacobians_match(bailey, s, Eigen::Vector2d(speed(rng), steer(rng)), dt);
    expect_jacobians_match(unicycle, s, Eigen::Vector2d(speed(rng), rate(rng)), dt);
    expect_jacobians_match(ackermann, s, Eigen::Vector2d(speed(rng), steer(rng)), dt);
    BrownianVelocityModel::State b;
    b << s, speed(rng), rate(rng);
    expect_jacobians_match(brownian, b, Eigen::Vector2d(0.1 * rate(rng), 0.1 * rate(rng)), dt);
    // Speed of both signs, curvature of both signs (up to a 2 m radius), nonzero increments.
    BrownianCurvatureModel::State k;
    k << s, speed(rng), 0.5 * rate(rng);
    expect_jacobians_match(curvature, k, Eigen::Vector2d(0.1 * rate(rng), 0.01 * rate(rng)), dt);
    expect_jacobians_match(linear, s.head<2>().eval(), Eigen::Vector2d(rate(rng), rate(rng)), dt);
    if (HasFailure()) {
      return;
    }
  }
}

TEST(MotionModelNoiseTest, PoseNoiseIsVMVt) {
  const AckermannModel model(kVictoriaParkCar);
  const Pose s(3.0, 4.0, -2.0);
  const Eigen::Vector2d u(4.0, 0.3);
  Eigen::Matrix2d m;
  m << 0.2, 0.01, 0.01, 0.025;
  const Eigen::Matrix<double, 3, 2> v = model.jacobian_control(s, u, 0.025);
  const Eigen::Matrix3d expected = v * m * v.transpose();
  const Eigen::Matrix3d p = model.pose_noise(s, u, 0.025, m);
  EXPECT_TRUE(matrices_near(p, expected, 1e-18, 1e-12));
  EXPECT_EQ(p, p.transpose());
  // Rank 2: the 3x3 determinant vanishes (relative to the scale of P).
  EXPECT_LT(std::abs(p.determinant()), 1e-12 * std::pow(p.diagonal().maxCoeff(), 3));
}

TEST(MotionModelNoiseTest, ZeroNormalsGiveThePrediction) {
  const BaileyCarModel model(4.0);
  const Pose s(1.0, 2.0, kPi - 0.01);
  const Eigen::Vector2d u(3.0, 0.1);
  const double zeros[2] = {0.0, 0.0};
  EXPECT_EQ(model.sample(s, u, 0.025, Eigen::Vector2d(0.3, 0.05), zeros),
            model.predict(s, u, 0.025));
}

// Sample mean and covariance of `sample` over many draws against predict and V M V^T. For n
// draws of a Gaussian the sample covariance entry S_ij has standard deviation
// sqrt((P_ii P_jj + P_ij^2) / n); we allow 5 of those. V M V^T is first order: the models are
// bilinear in speed and (a function of) steering, so the true covariance has extra terms of
// relative size (sigma_speed / speed)^2 and sigma_steer^2; the parameters below keep those at or
// under 1 % (Bailey's defaults: (0.3 / 3)^2 = 1 %), and we allow 1.5 % of sqrt(P_ii P_jj).
template <class Model>
void expect_sample_moments(const Model& model, const Pose& s, const Eigen::Vector2d& u, double dt,
                           const Eigen::Vector2d& sigmas, std::uint64_t seed) {
  constexpr int kDraws = 200000;
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  const Pose mean_expected = model.predict(s, u, dt);
  const Eigen::Matrix3d p = model.pose_noise(s, u, dt, Model::control_covariance(sigmas));
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d sum_sq = Eigen::Matrix3d::Zero();
  for (int i = 0; i < kDraws; ++i) {
    const double n[2] = {normal(rng), normal(rng)};
    Eigen::Vector3d d = model.sample(s, u, dt, sigmas, n) - mean_expected;
    d[2] = wrap_angle(d[2]);
    sum += d;
    sum_sq += d * d.transpose();
  }
  const Eigen::Vector3d mean = sum / kDraws;
  const Eigen::Matrix3d cov = sum_sq / kDraws - mean * mean.transpose();
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(mean[i], 0.0, 5.0 * std::sqrt(p(i, i) / kDraws) + 0.015 * std::sqrt(p(i, i)))
        << "mean component " << i;
    for (int j = 0; j < 3; ++j) {
      const double sd = std::sqrt((p(i, i) * p(j, j) + p(i, j) * p(i, j)) / kDraws);
      EXPECT_NEAR(cov(i, j), p(i, j), 5.0 * sd + 0.015 * std::sqrt(p(i, i) * p(j, j)))
          << "covariance (" << i << ", " << j << ")";
    }
  }
}

TEST(MotionModelNoiseTest, SampleCovarianceMatchesPoseNoise) {
  // Bailey's defaults: V = 3 m/s, sigmaV = 0.3 m/s, sigmaG = 3 deg, dt = 0.025 s; the heading sits
  // on the seam so the wrap is exercised.
  expect_sample_moments(BaileyCarModel(4.0), Pose(5.0, -3.0, kPi - 1e-4), Eigen::Vector2d(3.0, 0.2),
                        0.025, Eigen::Vector2d(0.3, 0.05235988), 1);
  expect_sample_moments(UnicycleModel(), Pose(0.0, 0.0, 1.0), Eigen::Vector2d(2.0, 0.3), 0.1,
                        Eigen::Vector2d(0.2, 0.05), 2);
  expect_sample_moments(AckermannModel(kVictoriaParkCar), Pose(-67.65, -41.71, 0.66),
                        Eigen::Vector2d(3.0, 0.1), 0.025, Eigen::Vector2d(0.3, 0.05), 3);
}

// Dead reckoning over the whole Victoria Park odometry with the model, from the first GPS fix and
// the README's fitted heading of 38.0 deg, reproduces the README's independent check: end point
// DR (-158.4, -238.9). Each sample is integrated over the time to the next.
TEST(AckermannModelTest, DeadReckoningMatchesTheDatasetCheck) {
  FASTSLAM_REQUIRE_SHARED(shared);
  std::ifstream in(shared + "/data/victoria_park/odometry.csv");
  ASSERT_TRUE(in) << "cannot open odometry.csv";
  std::string line;
  std::getline(in, line);             // header
  std::vector<Eigen::Vector3d> rows;  // time, speed, steering
  while (std::getline(in, line)) {
    Eigen::Vector3d r;
    ASSERT_EQ(std::sscanf(line.c_str(), "%lf,%lf,%lf", &r[0], &r[1], &r[2]), 3) << line;
    rows.push_back(r);
  }
  ASSERT_EQ(rows.size(), 61945u);
  const AckermannModel model(kVictoriaParkCar);
  Pose s(-67.649271, -41.714218, 38.0 * kPi / 180.0);
  for (std::size_t i = 0; i + 1 < rows.size(); ++i) {
    s = model.predict(s, rows[i].tail<2>(), rows[i + 1][0] - rows[i][0]);
  }
  // The README prints one decimal (we get (-158.39, -238.91)); a wrong lever arm or encoder
  // correction moves the end point by metres (a = 0.95 instead of 3.78: 4.4 m).
  EXPECT_NEAR(s[0], -158.4, 0.1);
  EXPECT_NEAR(s[1], -238.9, 0.1);
}

}  // namespace
}  // namespace fastslam::engine
