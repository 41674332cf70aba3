#include "engine/measurement_model.h"

#include <cmath>
#include <random>
#include <stdexcept>

#include <Eigen/Core>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include "tests/engine/test_util.h"

namespace fastslam::engine {
namespace {

using testing::matrices_near;
using testing::numeric_jacobian;
using testing::random_heading;

constexpr std::array<bool, 2> kBearing = {false, true};  // (range, bearing): bearing is an angle
constexpr std::array<bool, 2> kPositions = {false, false};

// A pose and a landmark 1..60 m from the sensor, a quarter of the time straight behind the
// vehicle (bearing within 1e-3 of +-pi), a quarter of the time with the heading on the seam.
struct Case {
  Pose pose;
  Eigen::Vector2d landmark;
};
Case random_case(std::mt19937_64& rng, const RangeBearingModel& model) {
  std::uniform_real_distribution<double> pos(-200.0, 200.0);
  std::uniform_real_distribution<double> range(1.0, 60.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  Case c;
  c.pose = {pos(rng), pos(rng), random_heading(rng)};
  const double bearing = unit(rng) < 0.25
                             ? (unit(rng) < 0.5 ? kPi : -kPi) + (unit(rng) - 0.5) * 2e-3
                             : random_heading(rng);
  c.landmark = model.landmark_from({range(rng), bearing}, c.pose);
  return c;
}

// ALGORITHM.md's matrices, written out independently (sensor at the pose).
void reference_jacobians(const Eigen::Vector2d& mu, const Pose& s, Eigen::Matrix2d& g_mu,
                         Eigen::Matrix<double, 2, 3>& g_s) {
  const double dx = mu[0] - s[0];
  const double dy = mu[1] - s[1];
  const double q = dx * dx + dy * dy;
  const double sq = std::sqrt(q);
  g_mu << dx / sq, dy / sq, -dy / q, dx / q;
  g_s << -dx / sq, -dy / sq, 0.0, dy / q, -dx / q, -1.0;
}

TEST(RangeBearingModelTest, PredictIsRangeAndWrappedBearing) {
  const RangeBearingModel model;
  const Eigen::Vector2d z = model.predict({3.0, 4.0}, Pose(0.0, 0.0, 0.0));
  EXPECT_DOUBLE_EQ(z[0], 5.0);
  EXPECT_DOUBLE_EQ(z[1], std::atan2(4.0, 3.0));
  // Behind the vehicle, heading near -pi: the raw difference leaves (-pi, pi].
  const Eigen::Vector2d back = model.predict({-1.0, -0.01}, Pose(0.0, 0.0, 3.0));
  EXPECT_GT(back[1], -kPi);
  EXPECT_LE(back[1], kPi);
  EXPECT_NEAR(back[1], wrap_angle(std::atan2(-0.01, -1.0) - 3.0), 1e-15);
}

TEST(RangeBearingModelTest, OffsetMovesTheSensor) {
  const RangeBearingModel model(SensorOffset{2.0, 0.5, 0.1});
  const Pose s(1.0, 1.0, kPi / 2);
  const Eigen::Vector2d p = model.sensor_position(s);
  EXPECT_NEAR(p[0], 1.0 - 0.5, 1e-12);  // forward is +y, left is -x
  EXPECT_NEAR(p[1], 1.0 + 2.0, 1e-12);
  const Eigen::Vector2d z = model.predict({p[0], p[1] + 10.0}, s);
  EXPECT_NEAR(z[0], 10.0, 1e-12);
  EXPECT_NEAR(z[1], -0.1, 1e-12);  // straight ahead of the vehicle, the sensor yawed 0.1 left
  EXPECT_THROW(RangeBearingModel(SensorOffset{std::nan(""), 0.0, 0.0}), std::invalid_argument);
}

TEST(RangeBearingModelTest, ZeroOffsetJacobiansAreTheAlgorithmMatrices) {
  const RangeBearingModel model;
  std::mt19937_64 rng(3);
  for (int i = 0; i < 200; ++i) {
    const Case c = random_case(rng, model);
    Eigen::Matrix2d g_mu;
    Eigen::Matrix<double, 2, 3> g_s;
    reference_jacobians(c.landmark, c.pose, g_mu, g_s);
    const auto lin = model.linearize(c.landmark, c.pose);
    ASSERT_TRUE(matrices_near(lin.g_landmark, g_mu, 1e-15, 1e-13));
    ASSERT_TRUE(matrices_near(lin.g_pose, g_s, 1e-15, 1e-13));
    ASSERT_TRUE(matrices_near(lin.z_hat, model.predict(c.landmark, c.pose), 0.0, 1e-14));
  }
}

// G_mu and G_s against central differences (bearing differences wrapped), with and without a
// sensor offset, at many random points including bearings and headings near +-pi.
TEST(RangeBearingModelTest, JacobiansMatchCentralDifferences) {
  for (const SensorOffset& offset :
       {SensorOffset{}, SensorOffset{3.78, 0.5, 0.0}, SensorOffset{-1.0, -2.0, 0.7}}) {
    const RangeBearingModel model(offset);
    std::mt19937_64 rng(11);
    for (int i = 0; i < 2000; ++i) {
      const Case c = random_case(rng, model);
      const auto lin = model.linearize(c.landmark, c.pose);
      const auto num_mu = numeric_jacobian<2, 2>(
          [&](const Eigen::Vector2d& m) { return model.predict(m, c.pose); }, c.landmark, kBearing);
      const auto num_s = numeric_jacobian<2, 3>(
          [&](const Eigen::Vector3d& s) { return model.predict(c.landmark, s); }, c.pose, kBearing);
      ASSERT_TRUE(matrices_near(lin.g_landmark, num_mu, 1e-8, 1e-6))
          << "offset (" << offset.x << ", " << offset.y << ") pose " << c.pose.transpose();
      ASSERT_TRUE(matrices_near(lin.g_pose, num_s, 1e-8, 1e-6))
          << "offset (" << offset.x << ", " << offset.y << ") pose " << c.pose.transpose();
      ASSERT_TRUE(matrices_near(model.jacobian_landmark(c.landmark, c.pose), lin.g_landmark, 0, 0));
      ASSERT_TRUE(matrices_near(model.jacobian_pose(c.landmark, c.pose), lin.g_pose, 0, 0));
    }
  }
}

TEST(RangeBearingModelTest, LongerStatesPadTheJacobianWithZeros) {
  const RangeBearingModel model(SensorOffset{1.0, 0.5, 0.0});
  Eigen::Matrix<double, 5, 1> state;
  state << 1.0, 2.0, 0.3, 4.0, 0.1;
  const Eigen::Vector2d lm(10.0, -5.0);
  const auto lin5 = model.linearize_state<5>(lm, state);
  const auto lin3 = model.linearize(lm, state.head<3>().eval());
  EXPECT_EQ(lin5.z_hat, lin3.z_hat);
  EXPECT_EQ(lin5.g_landmark, lin3.g_landmark);
  EXPECT_TRUE((lin5.g_pose.leftCols<3>().array() == lin3.g_pose.array()).all());
  EXPECT_TRUE(lin5.g_pose.rightCols<2>().isZero(0.0));
}

TEST(RangeBearingModelTest, InnovationWrapsTheBearing) {
  const Eigen::Vector2d v = RangeBearingModel::innovation({10.0, kPi - 0.01}, {9.5, -kPi + 0.01});
  EXPECT_DOUBLE_EQ(v[0], 0.5);
  EXPECT_NEAR(v[1], -0.02, 1e-12);
}

// landmark_from inverts predict; its Jacobians match central differences; d g^-1/dz = G_mu^-1.
TEST(RangeBearingModelTest, InverseModelAndItsJacobians) {
  for (const SensorOffset& offset : {SensorOffset{}, SensorOffset{3.78, 0.5, -0.3}}) {
    const RangeBearingModel model(offset);
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> range(0.5, 80.0);
    std::uniform_real_distribution<double> pos(-100.0, 100.0);
    for (int i = 0; i < 2000; ++i) {
      const Pose s(pos(rng), pos(rng), random_heading(rng));
      const Eigen::Vector2d z(range(rng), random_heading(rng));
      const Eigen::Vector2d mu = model.landmark_from(z, s);
      const Eigen::Vector2d back = model.predict(mu, s);
      ASSERT_NEAR(back[0], z[0], 1e-10 * z[0]);
      ASSERT_NEAR(angle_diff(back[1], z[1]), 0.0, 1e-10);
      const auto num_z = numeric_jacobian<2, 2>(
          [&](const Eigen::Vector2d& zz) { return model.landmark_from(zz, s); }, z, kPositions);
      const auto num_s = numeric_jacobian<2, 3>(
          [&](const Eigen::Vector3d& ss) { return model.landmark_from(z, ss); }, s, kPositions);
      const Eigen::Matrix2d j_z = model.inverse_jacobian_measurement(z, s);
      ASSERT_TRUE(matrices_near(j_z, num_z, 1e-7, 1e-6));
      ASSERT_TRUE(matrices_near(model.inverse_jacobian_pose(z, s), num_s, 1e-7, 1e-6));
      ASSERT_TRUE(
          matrices_near(j_z, model.linearize(mu, s).g_landmark.inverse().eval(), 1e-9, 1e-8));
    }
  }
}

}  // namespace
}  // namespace fastslam::engine
