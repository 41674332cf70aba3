#include "engine/angles.h"

#include <cmath>
#include <limits>
#include <random>

#include <gtest/gtest.h>

namespace fastslam::engine {
namespace {

TEST(WrapAngleTest, InRangeIsUnchanged) {
  for (double a : {0.0, 1.0, -1.0, kPi, -kPi + 1e-15, std::nextafter(-kPi, 0.0), 3.0, -3.0}) {
    EXPECT_EQ(wrap_angle(a), a) << a;
  }
}

TEST(WrapAngleTest, HalfOpenInterval) {
  EXPECT_EQ(wrap_angle(-kPi), kPi);
  EXPECT_EQ(wrap_angle(kPi), kPi);
  EXPECT_EQ(wrap_angle(3.0 * kPi), kPi);
  EXPECT_EQ(wrap_angle(-3.0 * kPi), kPi);
  EXPECT_EQ(wrap_angle(kTwoPi), 0.0);
  EXPECT_EQ(wrap_angle(-kTwoPi), 0.0);
  EXPECT_DOUBLE_EQ(wrap_angle(kPi + 0.5), -kPi + 0.5);
  EXPECT_DOUBLE_EQ(wrap_angle(-kPi - 0.5), kPi - 0.5);
  EXPECT_GT(wrap_angle(std::nextafter(kPi, 4.0)), -kPi);
  EXPECT_LE(wrap_angle(std::nextafter(-kPi, -4.0)), kPi);
}

TEST(WrapAngleTest, RandomAnglesLandInRangeAndDifferByWholeTurns) {
  std::mt19937_64 rng(7);
  for (double scale : {1.0, 4.0, 10.0, 1e3, 1e6}) {
    std::uniform_real_distribution<double> u(-scale * kPi, scale * kPi);
    for (int i = 0; i < 20000; ++i) {
      const double a = u(rng);
      const double w = wrap_angle(a);
      ASSERT_GT(w, -kPi) << a;
      ASSERT_LE(w, kPi) << a;
      const double turns = (a - w) / kTwoPi;
      ASSERT_NEAR(turns, std::round(turns), 1e-9 * std::max(1.0, std::abs(turns))) << a;
      ASSERT_NEAR(std::cos(w), std::cos(a), 1e-9 * scale) << a;
      ASSERT_NEAR(std::sin(w), std::sin(a), 1e-9 * scale) << a;
    }
  }
}

TEST(WrapAngleTest, IsIdempotent) {
  std::mt19937_64 rng(8);
  std::uniform_real_distribution<double> u(-100.0, 100.0);
  for (int i = 0; i < 10000; ++i) {
    const double w = wrap_angle(u(rng));
    ASSERT_EQ(wrap_angle(w), w);
  }
}

TEST(WrapAngleTest, NonFiniteGivesNan) {
  EXPECT_TRUE(std::isnan(wrap_angle(std::numeric_limits<double>::quiet_NaN())));
  EXPECT_TRUE(std::isnan(wrap_angle(std::numeric_limits<double>::infinity())));
  EXPECT_TRUE(std::isnan(wrap_angle(-std::numeric_limits<double>::infinity())));
}

TEST(AngleDiffTest, TakesTheShortWayAcrossTheSeam) {
  EXPECT_NEAR(angle_diff(kPi - 0.01, -kPi + 0.01), -0.02, 1e-12);
  EXPECT_NEAR(angle_diff(-kPi + 0.01, kPi - 0.01), 0.02, 1e-12);
  EXPECT_NEAR(angle_diff(0.3, 0.1), 0.2, 1e-15);
  EXPECT_EQ(angle_diff(kPi, -kPi), 0.0);
}

}  // namespace
}  // namespace fastslam::engine
