// The trajectory recorder against a direct weighted mean (long double sums), and its
// independence of how the motion stage splits the lanes into blocks (the groups are fixed) and
// of the controls beside a control in a pass. The ranks' fold is checked against one process in
// distributed_filter_test.
#include "engine/internal/trajectory_recorder.h"

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::engine::internal {
namespace {

constexpr std::size_t kG = TrajectorySums::kGroup;

// Poses x, y, theta of particle i after control k at [(k m + i) * 3]; the motion stage's
// blocks start at `cuts` (multiples of 8, the last m). Padding lanes get `pad` for every state.
std::vector<TrajectoryPoint> record(const std::vector<double>& log_weight,
                                    const std::vector<double>& poses, std::size_t controls,
                                    const std::vector<std::size_t>& cuts, double pad = 0.0) {
  TrajectoryRecorder recorder;
  recorder.points().push_back({99, 0, 0, 0});  // points not taken yet are kept
  recorder.begin(log_weight, controls);
  const TrajectorySums& sums = recorder.sums();
  const std::size_t m = log_weight.size();
  for (std::size_t c = 0; c + 1 < cuts.size(); ++c) {
    const std::size_t begin = cuts[c];
    const std::size_t lanes = (cuts[c + 1] - begin + kG - 1) / kG * kG;
    std::vector<double> w(lanes), x(lanes, pad), y(lanes, pad), theta(lanes, pad);
    sums.weights(begin, lanes, w.data());
    for (std::size_t k = 0; k < controls; ++k) {
      for (std::size_t l = 0; begin + l < cuts[c + 1]; ++l) {
        const double* p = &poses[(k * m + begin + l) * 3];
        x[l] = p[0];
        y[l] = p[1];
        theta[l] = p[2];
      }
      sums.add(k, begin, lanes, x.data(), y.data(), theta.data(), w.data());
    }
  }
  recorder.finish(controls, 7);
  return recorder.points();
}

TEST(TrajectoryRecorderTest, WeightedMeanPerControl) {
  constexpr std::size_t m = 1000, controls = 3;
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<double> log_weight(m), poses(controls * m * 3);
  for (double& l : log_weight) l = -700 + 5 * u(rng);  // far below zero: needs the max shift
  for (double& p : poses) p = 3 * u(rng);
  const std::vector<TrajectoryPoint> got = record(log_weight, poses, controls, {0, m});
  ASSERT_EQ(got.size(), controls + 1);
  EXPECT_EQ(got[0].control, 99u);
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
    const TrajectoryPoint& point = got[k + 1];
    EXPECT_EQ(point.control, 7 + k);
    EXPECT_NEAR(point.x, static_cast<double>(x / w), 1e-12);
    EXPECT_NEAR(point.y, static_cast<double>(y / w), 1e-12);
    EXPECT_NEAR(point.theta, std::atan2(static_cast<double>(s), static_cast<double>(c)), 1e-12);
  }
}

// A control's point does not depend on the block split (any cuts on whole groups, as the
// thread count changes them), on the padding lanes' states, or on the controls beside it in the
// pass: the bits of one block, one control at a time.
TEST(TrajectoryRecorderTest, AControlsPointIsTheSameWhateverThePassHolds) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (const std::size_t m : {1u, 7u, 8u, 9u, 255u, 256u, 257u, 1000u}) {
    constexpr std::size_t kControls = 9;
    std::vector<double> log_weight(m), poses(kControls * m * 3);
    for (double& l : log_weight) l = 20 * u(rng);
    for (double& p : poses) p = 50 * u(rng);
    std::vector<std::vector<std::size_t>> splits = {{0, m}};
    std::vector<std::size_t> eights = {0};
    for (std::size_t at = kG; at < m; at += kG) eights.push_back(at);
    eights.push_back(m);
    splits.push_back(eights);
    std::vector<std::size_t> random = {0};
    for (std::size_t at = kG * (1 + rng() % 5); at < m; at += kG * (1 + rng() % 5)) {
      random.push_back(at);
    }
    random.push_back(m);
    splits.push_back(random);
    for (const std::vector<std::size_t>& cuts : splits) {
      const std::vector<TrajectoryPoint> all =
          record(log_weight, poses, kControls, cuts, 1e6 * u(rng));
      ASSERT_EQ(all.size(), kControls + 1);
      for (std::size_t k = 0; k < kControls; ++k) {
        const std::vector<double> alone(poses.begin() + k * m * 3, poses.begin() + (k + 1) * m * 3);
        const TrajectoryPoint one = record(log_weight, alone, 1, {0, m})[1];
        EXPECT_EQ(all[k + 1].x, one.x) << "m " << m << " cuts " << cuts.size() << " k " << k;
        EXPECT_EQ(all[k + 1].y, one.y);
        EXPECT_EQ(all[k + 1].theta, one.theta);
      }
    }
  }
}

// The weights are those of the particles of each block: a block starting past the first group
// reads its own log-weights, and lanes past the last particle weigh nothing.
TEST(TrajectoryRecorderTest, WeightsOfABlock) {
  const std::vector<double> log_weight = {0, -1, -2, -3, -4, -5, -6, -7, -8, -9, -10};
  TrajectoryRecorder recorder;
  recorder.begin(log_weight, 1);
  const TrajectorySums& sums = recorder.sums();
  EXPECT_EQ(sums.groups, 2u);
  EXPECT_EQ(sums.shift, 0.0);
  std::vector<double> w(kG, std::numeric_limits<double>::quiet_NaN());
  sums.weights(kG, kG, w.data());
  for (std::size_t l = 0; l < 3; ++l) EXPECT_EQ(w[l], std::exp(log_weight[kG + l]));
  for (std::size_t l = 3; l < kG; ++l) EXPECT_EQ(w[l], 0.0);
}

}  // namespace
}  // namespace fastslam::engine::internal
