// The trajectory recorder against a direct weighted mean (long double sums), also inside the
// composed motion's runs, and its independence of how the motion stage splits the lanes into
// blocks (the groups are fixed) and of the controls beside a control in a pass. The ranks' fold is
// checked against one process in distributed_filter_test.
#include "engine/internal/trajectory_recorder.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "parallel/vector_math.h"

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

// The composed motion draw: the motion stage adds the sums at the pass's start and at each
// run's last control only, and the points inside a run are its start's weighted mean moved by
// the run's mean displacement: against brute force (long double, every particle moved), and
// bit-identical for any block split.
std::vector<TrajectoryPoint> record_runs(const std::vector<double>& log_weight,
                                         const std::vector<std::vector<double>>& ends,
                                         const std::vector<MotionRun>& runs,
                                         const std::vector<Eigen::Vector3d>& partial,
                                         const std::vector<std::size_t>& cuts) {
  TrajectoryRecorder recorder;
  recorder.begin(log_weight, partial.size());
  const TrajectorySums& sums = recorder.sums();
  for (std::size_t c = 0; c + 1 < cuts.size(); ++c) {
    const std::size_t begin = cuts[c];
    const std::size_t lanes = (cuts[c + 1] - begin + kG - 1) / kG * kG;
    std::vector<double> w(lanes);
    sums.weights(begin, lanes, w.data());
    // ends[0]: the poses at the pass's start; ends[r + 1]: after run r.
    auto lanes_of = [&](const std::vector<double>& poses, std::vector<double>& x,
                        std::vector<double>& y, std::vector<double>& theta) {
      x.assign(lanes, 0.0);
      y.assign(lanes, 0.0);
      theta.assign(lanes, 0.0);
      for (std::size_t l = 0; begin + l < cuts[c + 1]; ++l) {
        x[l] = poses[(begin + l) * 3];
        y[l] = poses[(begin + l) * 3 + 1];
        theta[l] = poses[(begin + l) * 3 + 2];
      }
    };
    std::vector<double> x, y, theta;
    lanes_of(ends[0], x, y, theta);
    sums.add_start(begin, lanes, x.data(), y.data(), theta.data(), w.data());
    for (std::size_t r = 0; r < runs.size(); ++r) {
      lanes_of(ends[r + 1], x, y, theta);
      sums.add(runs[r].first + runs[r].count - 1, begin, lanes, x.data(), y.data(), theta.data(),
               w.data());
    }
  }
  recorder.finish(partial.size(), 3, runs, partial);
  return recorder.points();
}

TEST(TrajectoryRecorderTest, APointInsideARunIsItsStartMovedByTheMeanDisplacement) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<MotionRun> runs(3);
  runs[0].first = 0, runs[0].count = 4;
  runs[1].first = 4, runs[1].count = 1;
  runs[2].first = 5, runs[2].count = 3;
  const std::size_t controls = 8;
  for (const std::size_t m : {1u, 9u, 64u, 301u}) {
    std::vector<double> log_weight(m);
    for (double& l : log_weight) l = 10 * u(rng);
    std::vector<std::vector<double>> ends(runs.size() + 1, std::vector<double>(3 * m));
    for (std::vector<double>& poses : ends) {
      for (double& p : poses) p = 20 * u(rng);
    }
    std::vector<Eigen::Vector3d> partial(controls);
    for (Eigen::Vector3d& d : partial) d = {2 * u(rng), 0.5 * u(rng), 0.3 * u(rng)};
    const std::vector<TrajectoryPoint> got = record_runs(log_weight, ends, runs, partial, {0, m});
    ASSERT_EQ(got.size(), controls);
    const double best = *std::max_element(log_weight.begin(), log_weight.end());
    for (std::size_t r = 0; r < runs.size(); ++r) {
      const std::size_t last = runs[r].first + runs[r].count - 1;
      for (std::size_t k = runs[r].first; k <= last; ++k) {
        // Inside the run: each particle of the run's start moved by partial[k]; at its last
        // control: the poses after the run.
        const std::vector<double>& from = k < last ? ends[r] : ends[r + 1];
        const Eigen::Vector3d d = k < last ? partial[k] : Eigen::Vector3d::Zero();
        long double w = 0, x = 0, y = 0, c = 0, s = 0;
        for (std::size_t i = 0; i < m; ++i) {
          const long double wi = std::exp(static_cast<long double>(log_weight[i] - best));
          const long double th = from[i * 3 + 2];
          w += wi;
          x += wi * (from[i * 3] + std::cos(th) * d[0] - std::sin(th) * d[1]);
          y += wi * (from[i * 3 + 1] + std::sin(th) * d[0] + std::cos(th) * d[1]);
          c += wi * std::cos(th + d[2]);
          s += wi * std::sin(th + d[2]);
        }
        const TrajectoryPoint& p = got[k];
        EXPECT_EQ(p.control, 3 + k);
        EXPECT_NEAR(p.x, static_cast<double>(x / w), 1e-11) << "m " << m << " k " << k;
        EXPECT_NEAR(p.y, static_cast<double>(y / w), 1e-11) << "m " << m << " k " << k;
        EXPECT_NEAR(p.theta, static_cast<double>(std::atan2(s, c)), 1e-12) << "m " << m;
      }
    }
    std::vector<std::size_t> eights = {0};
    for (std::size_t at = kG; at < m; at += kG) eights.push_back(at);
    eights.push_back(m);
    const std::vector<TrajectoryPoint> split = record_runs(log_weight, ends, runs, partial, eights);
    ASSERT_EQ(split.size(), controls);
    for (std::size_t k = 0; k < controls; ++k) {
      EXPECT_EQ(split[k].x, got[k].x);
      EXPECT_EQ(split[k].y, got[k].y);
      EXPECT_EQ(split[k].theta, got[k].theta);
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
  EXPECT_FALSE(sums.uniform);
  // After a resampling every log-weight is the same: each weight is exp(0) = 1, not computed.
  const std::vector<double> equal(11, -std::log(11.0));
  recorder.begin(equal, 1);
  EXPECT_TRUE(recorder.sums().uniform);
  recorder.sums().weights(kG, kG, w.data());
  for (std::size_t l = 0; l < 3; ++l) {
    EXPECT_EQ(w[l], parallel::exp_nonpositive(equal[kG + l] - recorder.sums().shift));
    EXPECT_EQ(w[l], 1.0);
  }
  for (std::size_t l = 3; l < kG; ++l) EXPECT_EQ(w[l], 0.0);
}

// The shift (the largest log-weight) and the uniform flag are std::minmax_element's values for
// every length (the four-lane loop and its tail), wherever the extremes sit, with ties, infinities
// and NaNs.
TEST(TrajectoryRecorderTest, ShiftAndUniformAreTheLogWeightsRange) {
  std::mt19937_64 rng(5);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  for (std::size_t m = 1; m <= 40; ++m) {
    for (int trial = 0; trial < 200; ++trial) {
      std::vector<double> l(m);
      const int kind = trial % 5;
      for (double& v : l) {
        v = kind == 0 ? -std::ldexp(static_cast<double>(rng() % 8), static_cast<int>(rng() % 3))
                      : -static_cast<double>(rng() % 1000) / 7.0;
      }
      if (kind == 2) l[rng() % m] = -inf;
      if (kind == 3) l[rng() % m] = nan;
      if (kind == 4) std::fill(l.begin(), l.end(), -2.5);
      TrajectoryRecorder recorder;
      recorder.begin(l, 1);
      const auto [lo, hi] = std::minmax_element(l.begin(), l.end());
      const TrajectorySums& sums = recorder.sums();
      if (std::isnan(*hi)) {
        EXPECT_TRUE(std::isnan(sums.shift)) << m;
      } else {
        EXPECT_EQ(sums.shift, *hi) << m << " " << kind;
      }
      EXPECT_EQ(sums.uniform, *lo == *hi) << m << " " << kind;
    }
  }
}

}  // namespace
}  // namespace fastslam::engine::internal
