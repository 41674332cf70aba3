// The trajectory recorder against a direct weighted mean (long double sums), and its
// independence of the kernel's thread count (the reduction's blocks are fixed) and of the
// controls beside a control in a pass.
#include "engine/internal/trajectory_recorder.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::engine::internal {
namespace {

std::vector<TrajectoryPoint> record(unsigned threads, const std::vector<double>& log_weight,
                                    const std::vector<double>& poses, std::size_t controls) {
  parallel::ParticleKernel kernel({threads, 64});
  TrajectoryRecorder recorder;
  recorder.points().push_back({99, 0, 0, 0});  // points not taken yet are kept
  recorder.begin(log_weight, controls);
  const std::size_t m = log_weight.size();
  for (std::size_t k = 0; k < controls; ++k) {
    for (std::size_t i = 0; i < m; ++i) {
      const double* p = &poses[(k * m + i) * 3];
      double* out = recorder.buffer() + (k * m + i) * 4;
      out[0] = p[0];
      out[1] = p[1];
      out[2] = std::cos(p[2]);
      out[3] = std::sin(p[2]);
    }
  }
  recorder.finish(kernel, controls, 7);
  return recorder.points();
}

TEST(TrajectoryRecorderTest, WeightedMeanPerControl) {
  constexpr std::size_t m = 1000, controls = 3;
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<double> log_weight(m), poses(controls * m * 3);
  for (double& l : log_weight) l = -700 + 5 * u(rng);  // far below zero: needs the max shift
  for (double& p : poses) p = 3 * u(rng);
  const std::vector<TrajectoryPoint> one = record(1, log_weight, poses, controls);
  const std::vector<TrajectoryPoint> two = record(2, log_weight, poses, controls);
  ASSERT_EQ(one.size(), controls + 1);
  EXPECT_EQ(one[0].control, 99u);
  for (std::size_t k = 0; k < controls; ++k) {
    long double w = 0, x = 0, y = 0, c = 0, s = 0;
    for (std::size_t i = 0; i < m; ++i) {
      const long double wi = std::exp(static_cast<long double>(log_weight[i]) + 700);
      const double* p = &poses[(k * m + i) * 3];
      w += wi;
      x += wi * p[0];
      y += wi * p[1];
      c += wi * std::cos(p[2]);
      s += wi * std::sin(p[2]);
    }
    const TrajectoryPoint& got = one[k + 1];
    EXPECT_EQ(got.control, 7 + k);
    EXPECT_NEAR(got.x, static_cast<double>(x / w), 1e-12);
    EXPECT_NEAR(got.y, static_cast<double>(y / w), 1e-12);
    EXPECT_NEAR(got.theta, std::atan2(static_cast<double>(s), static_cast<double>(c)), 1e-12);
    EXPECT_EQ(got.x, two[k + 1].x);
    EXPECT_EQ(got.theta, two[k + 1].theta);
  }
}

// A control's point does not depend on the controls beside it in the pass (the sums of a
// block's controls are interleaved, each in particle order) nor on the thread count: a pass of
// K controls gives the bits of K passes of one, for block edges on both sides of the count.
TEST(TrajectoryRecorderTest, AControlsPointIsTheSameWhateverThePassHolds) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (const std::size_t m : {1u, 255u, 256u, 257u, 1000u}) {
    constexpr std::size_t kControls = 9;  // two groups of four and one alone
    std::vector<double> log_weight(m), poses(kControls * m * 3);
    for (double& l : log_weight) l = 20 * u(rng);
    for (double& p : poses) p = 50 * u(rng);
    for (const unsigned threads : {1u, 2u}) {
      const std::vector<TrajectoryPoint> all = record(threads, log_weight, poses, kControls);
      ASSERT_EQ(all.size(), kControls + 1);
      for (std::size_t k = 0; k < kControls; ++k) {
        const std::vector<double> alone(poses.begin() + k * m * 3, poses.begin() + (k + 1) * m * 3);
        const TrajectoryPoint one = record(1, log_weight, alone, 1)[1];
        EXPECT_EQ(all[k + 1].x, one.x) << "m " << m << " threads " << threads << " k " << k;
        EXPECT_EQ(all[k + 1].y, one.y);
        EXPECT_EQ(all[k + 1].theta, one.theta);
      }
    }
  }
}

}  // namespace
}  // namespace fastslam::engine::internal
