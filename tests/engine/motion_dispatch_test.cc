#include "engine/motion_dispatch.h"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include <Eigen/Core>
#include <gtest/gtest.h>

#include "tests/engine/test_util.h"

namespace fastslam::engine {
namespace {

constexpr MotionKind kKinds[] = {MotionKind::kBaileyCar, MotionKind::kUnicycle,
                                 MotionKind::kAckermann, MotionKind::kBrownian,
                                 MotionKind::kBrownianCurvature};

// The kind each model type stands for, written out independently of the dispatch.
template <class Model>
MotionKind kind_of() {
  if constexpr (std::is_same_v<Model, BaileyCarModel>) return MotionKind::kBaileyCar;
  if constexpr (std::is_same_v<Model, UnicycleModel>) return MotionKind::kUnicycle;
  if constexpr (std::is_same_v<Model, AckermannModel>) return MotionKind::kAckermann;
  if constexpr (std::is_same_v<Model, BrownianVelocityModel>) return MotionKind::kBrownian;
  if constexpr (std::is_same_v<Model, BrownianCurvatureModel>) {
    return MotionKind::kBrownianCurvature;
  }
}

TEST(MotionDispatchTest, VisitBuildsTheModelTheKindNamesWithItsParameters) {
  for (const MotionKind kind : kKinds) {
    SCOPED_TRACE(std::string(enum_name(kind)));
    MotionConfig config;
    config.kind = kind;
    config.wheelbase = 2.5;
    config.geometry = testing::kVictoriaParkCar;
    const MotionKind built = visit_motion(config, [&](const auto& model) {
      using Model = std::decay_t<decltype(model)>;
      if constexpr (std::is_same_v<Model, BaileyCarModel>) {
        EXPECT_EQ(model.wheelbase(), 2.5);
      } else if constexpr (std::is_same_v<Model, AckermannModel>) {
        EXPECT_EQ(model.geometry().a, 3.78);
        EXPECT_EQ(model.geometry().h, 0.76);
      }
      EXPECT_EQ(without_odometry(kind), Model::kNoOdometry);
      EXPECT_EQ(motion_state_dim(kind), Model::kStateDim);
      return kind_of<Model>();
    });
    EXPECT_EQ(built, kind);
  }
}

// The models without odometry are exactly the Brownian walks, with the velocities in the state.
TEST(MotionDispatchTest, OdometryAndStateDimension) {
  EXPECT_FALSE(without_odometry(MotionKind::kBaileyCar));
  EXPECT_FALSE(without_odometry(MotionKind::kUnicycle));
  EXPECT_FALSE(without_odometry(MotionKind::kAckermann));
  EXPECT_TRUE(without_odometry(MotionKind::kBrownian));
  EXPECT_TRUE(without_odometry(MotionKind::kBrownianCurvature));
  EXPECT_EQ(motion_state_dim(MotionKind::kAckermann), 3);
  EXPECT_EQ(motion_state_dim(MotionKind::kBrownianCurvature), 5);
  EXPECT_THROW(without_odometry(static_cast<MotionKind>(77)), std::invalid_argument);
}

// Each parameter's setter and getter address the same field, the one the model is built from.
TEST(MotionDispatchTest, ParametersReadAndWriteTheirFields) {
  EXPECT_EQ(motion_parameters(MotionKind::kBaileyCar).size(), 1u);
  EXPECT_EQ(motion_parameters(MotionKind::kAckermann).size(), 4u);
  EXPECT_TRUE(motion_parameters(MotionKind::kUnicycle).empty());
  EXPECT_TRUE(motion_parameters(MotionKind::kBrownian).empty());
  EXPECT_TRUE(motion_parameters(MotionKind::kBrownianCurvature).empty());
  EXPECT_TRUE(motion_parameters(static_cast<MotionKind>(77)).empty());
  MotionConfig c;
  c.kind = MotionKind::kAckermann;
  const std::vector<double> values = {1.5, -0.25, 2.75, 0.5};
  const auto parameters = motion_parameters(c.kind);
  for (std::size_t i = 0; i < parameters.size(); ++i) parameters[i].set(c, values[i]);
  EXPECT_EQ(c.geometry.a, 1.5);
  EXPECT_EQ(c.geometry.b, -0.25);
  EXPECT_EQ(c.geometry.l, 2.75);
  EXPECT_EQ(c.geometry.h, 0.5);
  for (std::size_t i = 0; i < parameters.size(); ++i) EXPECT_EQ(parameters[i].get(c), values[i]);
  visit_motion(c, [](const auto& model) {
    if constexpr (std::is_same_v<std::decay_t<decltype(model)>, AckermannModel>) {
      EXPECT_EQ(model.geometry().l, 2.75);
    }
  });
  motion_parameters(MotionKind::kBaileyCar)[0].set(c, 7.0);
  EXPECT_EQ(c.wheelbase, 7.0);
}

TEST(MotionDispatchTest, EveryKindsDefaultIsValidAndBadFieldsAreNamed) {
  for (const MotionKind kind : kKinds) {
    MotionConfig c;
    c.kind = kind;
    EXPECT_NO_THROW(validate(c)) << enum_name(kind);
  }
  auto message = [](const MotionConfig& c) -> std::string {
    try {
      validate(c);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "(valid)";
  };
  MotionConfig c;
  c.wheelbase = -1.0;
  EXPECT_NE(message(c).find("wheelbase"), std::string::npos) << message(c);
  c.kind = MotionKind::kUnicycle;  // the wheelbase is not the unicycle's
  EXPECT_EQ(message(c), "(valid)");
  c.kind = MotionKind::kAckermann;
  c.geometry.h = -0.1;
  EXPECT_NE(message(c).find("geometry"), std::string::npos) << message(c);
  c.geometry.h = 0.0;
  c.geometry.a = std::numeric_limits<double>::quiet_NaN();
  EXPECT_NE(message(c).find("geometry"), std::string::npos) << message(c);
  c = MotionConfig{};
  c.sigma_control[1] = -0.01;
  EXPECT_NE(message(c).find("motion.sigma_control[1]"), std::string::npos) << message(c);
  c = MotionConfig{};
  c.kind = static_cast<MotionKind>(77);
  EXPECT_NE(message(c).find("motion.kind"), std::string::npos) << message(c);
  EXPECT_THROW(visit_motion(c, [](const auto&) {}), std::invalid_argument);
}

}  // namespace
}  // namespace fastslam::engine
