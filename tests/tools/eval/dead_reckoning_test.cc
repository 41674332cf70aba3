#include "tools/eval/dead_reckoning.h"

#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "engine/motion_model.h"

namespace fastslam::tools {
namespace {

// A unicycle driven straight at 1 m/s for 10 s, then a quarter turn in place: the pose by hand.
TEST(DeadReckoning, IntegratesTheUnicycleExactly) {
  engine::MotionConfig motion;
  motion.kind = engine::MotionKind::kUnicycle;
  const double start[3] = {1.0, 2.0, 0.0};
  DeadReckoning dr(motion, start, 5.0);
  ASSERT_TRUE(dr.available());
  EXPECT_EQ(dr.pose().time, 5.0);
  for (int k = 1; k <= 100; ++k) dr.predict({1.0, 0.0}, 0.1, 5.0 + 0.1 * k);
  EXPECT_NEAR(dr.pose().x, 11.0, 1e-9);
  EXPECT_NEAR(dr.pose().y, 2.0, 1e-12);
  for (int k = 1; k <= 10; ++k) dr.predict({0.0, std::numbers::pi / 2}, 0.1, 15.0 + 0.1 * k);
  EXPECT_NEAR(dr.pose().theta, std::numbers::pi / 2, 1e-12);
  EXPECT_NEAR(dr.pose().time, 16.0, 1e-12);
}

// Bailey's car: the model's own prediction, step for step.
TEST(DeadReckoning, FollowsTheSourcesModel) {
  engine::MotionConfig motion;  // Bailey's car, wheelbase 4
  const double start[3] = {0.0, 0.0, 0.3};
  DeadReckoning dr(motion, start, 0.0);
  const engine::BaileyCarModel car(4.0);
  engine::BaileyCarModel::State s(0.0, 0.0, 0.3);
  for (int k = 1; k <= 50; ++k) {
    dr.predict({3.0, 0.1}, 0.025, 0.025 * k);
    s = car.predict(s, {3.0, 0.1}, 0.025);
  }
  EXPECT_EQ(dr.pose().x, s[0]);
  EXPECT_EQ(dr.pose().y, s[1]);
  EXPECT_EQ(dr.pose().theta, s[2]);
}

// A model that ignores the controls has no dead reckoning: the pose stays, the time moves.
TEST(DeadReckoning, NoBaselineWithoutOdometry) {
  engine::MotionConfig motion;
  motion.kind = engine::MotionKind::kBrownian;
  const double start[3] = {4.0, 5.0, 1.0};
  DeadReckoning dr(motion, start, 0.0);
  EXPECT_FALSE(dr.available());
  dr.predict({2.0, 1.0}, 1.0, 1.0);
  EXPECT_EQ(dr.pose().x, 4.0);
  EXPECT_EQ(dr.pose().time, 1.0);
}

}  // namespace
}  // namespace fastslam::tools
