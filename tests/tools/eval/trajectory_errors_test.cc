#include "tools/eval/trajectory_errors.h"

#include <cmath>
#include <numbers>
#include <optional>
#include <random>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::tools {
namespace {

TEST(PoseAt, ExactInterpolatedOrNothing) {
  const std::vector<StampedPose> samples = {
      {0.0, 0.0, 0.0, 3.0}, {0.5, 1.0, 2.0, -3.0}, {0.5, 1.5, 2.5, 0.0}, {2.0, 9.0, 9.0, 0.0}};
  // Exact: the last sample stamped t.
  ASSERT_TRUE(pose_at(samples, 0.5));
  EXPECT_EQ(pose_at(samples, 0.5)->x, 1.5);
  // Between 0 and 0.5: linear in x, y; the heading along the short way round through pi.
  const std::optional<StampedPose> p = pose_at(samples, 0.25);
  ASSERT_TRUE(p);
  EXPECT_DOUBLE_EQ(p->x, 0.5);
  EXPECT_DOUBLE_EQ(p->y, 1.0);
  EXPECT_NEAR(std::abs(p->theta), std::numbers::pi, 0.15);
  EXPECT_NEAR(std::abs(p->theta), 3.0 + (2 * std::numbers::pi - 6.0) / 2, 1e-12);
  // A gap wider than kMaxInterpolationGap, and outside the samples: nothing.
  EXPECT_FALSE(pose_at(samples, 1.0));
  EXPECT_FALSE(pose_at(samples, -0.1));
  EXPECT_FALSE(pose_at(samples, 2.1));
}

TEST(PositionErrors, CountsUsedAndSkippedReferences) {
  const std::vector<StampedPose> estimate = {{0.0, 0.0, 0.0, 0.0}, {1.0, 1.0, 0.0, 0.0}};
  const std::vector<StampedPose> reference = {
      {0.0, 0.0, 3.0, 0.0}, {0.5, 0.5, 4.0, 0.0}, {5.0, 0.0, 0.0, 0.0}};
  const PositionErrors e = position_errors(estimate, reference);
  EXPECT_EQ(e.used, 2u);
  EXPECT_EQ(e.skipped, 1u);
  EXPECT_DOUBLE_EQ(e.rmse, std::sqrt((9.0 + 16.0) / 2));
  EXPECT_DOUBLE_EQ(e.last, 4.0);
  EXPECT_EQ(position_errors(estimate, {}).rmse, 0.0);
}

// Oracle: a reference that is the estimate moved rigidly aligns back with no error, and the
// rotation found undoes the one applied.
TEST(AlignedPositionErrors, RecoverARigidMotion) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-50.0, 50.0);
  std::vector<StampedPose> estimate, reference;
  const double angle = 0.3, c = std::cos(angle), s = std::sin(angle);
  for (int i = 0; i < 40; ++i) {
    const double x = u(rng), y = u(rng);
    estimate.push_back({0.1 * i, x, y, 0.0});
    reference.push_back({0.1 * i, c * x - s * y + 7.0, s * x + c * y - 2.0, 0.0});
  }
  const AlignedErrors a = aligned_position_errors(estimate, reference);
  EXPECT_NEAR(a.rotation, angle, 1e-12);
  EXPECT_NEAR(a.rmse, 0.0, 1e-9);
  EXPECT_GT(position_errors(estimate, reference).rmse, 1.0);
  EXPECT_EQ(aligned_position_errors(estimate, {}).rmse, 0.0);
}

TEST(LandmarkRmseById, PairsByIdAndRefusesUnknownIds) {
  const std::vector<TruthLandmark> truth = {{5, 0.0, 0.0}, {2, 10.0, 0.0}};
  std::vector<engine::MapLandmark> map(2);
  map[0].id = 2;
  map[0].x = 13.0;
  map[1].id = 5;
  map[1].y = 4.0;
  EXPECT_DOUBLE_EQ(landmark_rmse_by_id(map, truth), std::sqrt((9.0 + 16.0) / 2));
  EXPECT_EQ(landmark_rmse_by_id({}, truth), 0.0);
  map[1].id = 6;
  EXPECT_THROW(landmark_rmse_by_id(map, truth), std::runtime_error);
}

}  // namespace
}  // namespace fastslam::tools
