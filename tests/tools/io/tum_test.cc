#include "tools/io/tum.h"

#include <cmath>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::tools {
namespace {

TEST(Tum, YawQuaternionRotatesAboutZ) {
  for (double yaw : {0.0, 0.3, -1.2, std::numbers::pi / 2, 3.0, -3.1}) {
    const auto [qx, qy, qz, qw] = yaw_quaternion(yaw);
    EXPECT_EQ(qx, 0.0);
    EXPECT_EQ(qy, 0.0);
    EXPECT_NEAR(qx * qx + qy * qy + qz * qz + qw * qw, 1.0, 1e-15);
    // The rotation matrix's first column (1 - 2 qz^2, 2 qz qw) is (cos yaw, sin yaw).
    EXPECT_NEAR(1 - 2 * qz * qz, std::cos(yaw), 1e-15);
    EXPECT_NEAR(2 * qz * qw, std::sin(yaw), 1e-15);
  }
}

TEST(Tum, WritesEightColumnsPerPoseExactly) {
  const std::vector<StampedPose> poses = {{0.025, 1.5, -2.25, 0.0},
                                          {1570.54, 0.1, 1e-20, std::numbers::pi / 2}};
  std::ostringstream out;
  write_tum(out, poses);
  std::istringstream in(out.str());
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "# timestamp tx ty tz qx qy qz qw");
  std::getline(in, line);
  EXPECT_EQ(line, "0.025 1.5 -2.25 0 0 0 0 1");
  std::getline(in, line);
  std::istringstream fields(line);
  std::vector<double> v;
  for (double x; fields >> x;) v.push_back(x);
  ASSERT_EQ(v.size(), 8u);
  EXPECT_EQ(v[0], 1570.54);
  EXPECT_EQ(v[1], 0.1);
  EXPECT_EQ(v[2], 1e-20);  // exact, not rounded to a fixed number of decimals
  EXPECT_EQ(v[3], 0.0);
  EXPECT_EQ(v[6], std::sin(std::numbers::pi / 4));
  EXPECT_EQ(v[7], std::cos(std::numbers::pi / 4));
  EXPECT_FALSE(std::getline(in, line));
}

TEST(Tum, RefusesNonFinitePosesWritingNothing) {
  std::ostringstream out;
  const std::vector<StampedPose> poses = {{0.0, 1, 2, 3}, {1.0, NAN, 0, 0}};
  EXPECT_THROW(write_tum(out, poses), std::invalid_argument);
  EXPECT_TRUE(out.str().empty());
}

}  // namespace
}  // namespace fastslam::tools
