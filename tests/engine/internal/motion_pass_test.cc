// The motion stage against the scalar motion models (engine/motion_model.h) driven by the same
// keyed streams: FastSLAM 1.0 samples each control with the particle's (seed, step, particle,
// kMotion) normals, 2.0 propagates mean and covariance (P <- J P J^T + V M V^T). Also: the
// result does not depend on the block split or on normals taken from the ahead window, and the
// recorded trajectory is the weighted mean of the states after each control.
#include "engine/internal/motion_pass.h"

#include <array>
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "engine/internal/motion_normals_ahead.h"
#include "engine/motion_model.h"
#include "memory/node_heap.h"
#include "parallel/particle_kernel.h"

namespace fastslam::engine::internal {
namespace {

constexpr std::uint64_t kSeed = 42;

struct Fixture {
  memory::PoolHeap heap;
  memory::ParticleStore store;
  PoseCovariances cov;
  std::vector<PendingControl> pending;

  Fixture(std::size_t m, std::size_t controls, bool no_odometry, std::uint64_t rng_seed)
      : store(m, heap, {memory::Indexing::kNone, memory::PoseCovariance::kScratch}), cov(store) {
    std::mt19937_64 rng(rng_seed);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (std::size_t i = 0; i < m; ++i) {
      store.x()[i] = 10 * u(rng);
      store.y()[i] = 10 * u(rng);
      store.theta()[i] = 3 * u(rng);
      store.v()[i] = 2 + u(rng);
      store.omega()[i] = 0.2 * u(rng);
    }
    for (std::size_t k = 0; k < controls; ++k) {
      const double a = no_odometry ? 0.0 : 3 + u(rng);
      const double b = no_odometry ? 0.0 : 0.3 * u(rng);
      pending.push_back({a, b, 0.05 + 0.05 * (1 + u(rng)), 3 + 2 * k});
    }
  }
};

template <class Motion, bool kFs2>
void advance(const Motion& motion, Fixture& f, std::vector<std::size_t> cuts,
             const MotionNormalsWindow& window, const TrajectorySums* record) {
  MotionInput in;
  in.pending = f.pending;
  in.seed = kSeed;
  in.sigma_control[0] = 0.3;
  in.sigma_control[1] = 0.05;
  in.ahead = &window;
  MotionScratch scratch;
  for (std::size_t c = 0; c + 1 < cuts.size(); ++c) {
    advance_block<Motion, kFs2>(motion, in, f.store, f.cov, cuts[c], cuts[c + 1] - cuts[c], record,
                                scratch);
  }
}

template <class Motion>
typename Motion::State state_of(const Fixture& f, std::size_t i) {
  const double all[5] = {f.store.x()[i], f.store.y()[i], f.store.theta()[i], f.store.v()[i],
                         f.store.omega()[i]};
  typename Motion::State s;
  for (int k = 0; k < Motion::kStateDim; ++k) s[k] = all[k];
  return s;
}

template <class Motion>
void expect_sampling_matches_scalar(const Motion& motion) {
  constexpr std::size_t m = 37;
  Fixture f(m, 5, Motion::kNoOdometry, 1);
  Fixture start(m, 5, Motion::kNoOdometry, 1);
  std::vector<double> log_weight(m);
  for (std::size_t i = 0; i < m; ++i) log_weight[i] = -0.1 * static_cast<double>(i % 7);
  TrajectoryRecorder recorder;
  recorder.begin(log_weight, f.pending.size());
  advance<Motion, false>(motion, f, {0, 16, 24, m}, MotionNormalsWindow{}, &recorder.sums());
  recorder.finish(f.pending.size(), 0);
  const typename Motion::Control sigmas(0.3, 0.05);
  // Per control: the sums of w, w x, w y, w cos, w sin over the scalar models' states.
  std::vector<std::array<double, 5>> mean(f.pending.size(), std::array<double, 5>{});
  for (std::size_t i = 0; i < m; ++i) {
    const double w = std::exp(log_weight[i]);
    typename Motion::State s = state_of<Motion>(start, i);
    for (std::size_t k = 0; k < f.pending.size(); ++k) {
      const PendingControl& c = f.pending[k];
      double n[2];
      parallel::normal_pairs_for_particles(kSeed, c.step, parallel::Purpose::kMotion,
                                           static_cast<std::uint32_t>(i), 1, {&n[0], 1},
                                           {&n[1], 1});
      s = motion.sample(s, typename Motion::Control(c.u0, c.u1), c.dt, sigmas, n);
      const std::array<double, 5> terms = {w, w * s[0], w * s[1], w * std::cos(s[2]),
                                           w * std::sin(s[2])};
      for (int t = 0; t < 5; ++t) mean[k][t] += terms[t];
    }
    const typename Motion::State got = state_of<Motion>(f, i);
    for (int k = 0; k < Motion::kStateDim; ++k) EXPECT_NEAR(got[k], s[k], 1e-9) << i << " " << k;
  }
  const std::vector<TrajectoryPoint>& points = recorder.points();
  ASSERT_EQ(points.size(), f.pending.size());
  for (std::size_t k = 0; k < points.size(); ++k) {
    EXPECT_EQ(points[k].control, k);
    EXPECT_NEAR(points[k].x, mean[k][1] / mean[k][0], 1e-9);
    EXPECT_NEAR(points[k].y, mean[k][2] / mean[k][0], 1e-9);
    EXPECT_NEAR(points[k].theta, std::atan2(mean[k][4], mean[k][3]), 1e-9);
  }
}

template <class Motion>
void expect_prediction_matches_scalar(const Motion& motion) {
  constexpr int N = Motion::kStateDim;
  constexpr std::size_t m = 21;
  Fixture f(m, 4, Motion::kNoOdometry, 2);
  Fixture start(m, 4, Motion::kNoOdometry, 2);
  for (std::size_t i = 0; i < m; ++i) {
    f.cov.at<N>(i).setIdentity();
    f.cov.at<N>(i) *= 0.01 * static_cast<double>(i + 1);
  }
  advance<Motion, true>(motion, f, {0, 8, m}, MotionNormalsWindow{}, nullptr);
  const typename Motion::Control sigmas(0.3, 0.05);
  const auto control_cov = Motion::control_covariance(sigmas);
  for (std::size_t i = 0; i < m; ++i) {
    typename Motion::State s = state_of<Motion>(start, i);
    Eigen::Matrix<double, N, N> p =
        Eigen::Matrix<double, N, N>::Identity() * 0.01 * static_cast<double>(i + 1);
    for (const PendingControl& c : f.pending) {
      const typename Motion::Control u(c.u0, c.u1);
      const auto j = motion.jacobian_pose(s, u, c.dt);
      p = j * p * j.transpose() + motion.pose_noise(s, u, c.dt, control_cov);
      s = motion.predict(s, u, c.dt);
    }
    const typename Motion::State got = state_of<Motion>(f, i);
    for (int k = 0; k < N; ++k) EXPECT_NEAR(got[k], s[k], 1e-9);
    const Eigen::Matrix<double, N, N> got_p = f.cov.at<N>(i);
    EXPECT_TRUE(got_p.isApprox(p, 1e-9)) << got_p << "\n\n" << p;
    EXPECT_EQ(got_p, got_p.transpose());
  }
}

TEST(MotionPassTest, SamplingMatchesTheScalarModels) {
  expect_sampling_matches_scalar(BaileyCarModel(4.0));
  expect_sampling_matches_scalar(BrownianVelocityModel());
}

TEST(MotionPassTest, PredictionMatchesTheScalarModels) {
  expect_prediction_matches_scalar(UnicycleModel());
  expect_prediction_matches_scalar(BrownianVelocityModel());
}

TEST(MotionPassTest, BlocksAndTheAheadWindowChangeNoBit) {
  constexpr std::size_t m = 40;
  const BaileyCarModel motion(4.0);
  Fixture one(m, 6, false, 3), split(m, 6, false, 3), ahead(m, 6, false, 3);
  advance<BaileyCarModel, false>(motion, one, {0, m}, MotionNormalsWindow{}, nullptr);
  advance<BaileyCarModel, false>(motion, split, {0, 8, 32, m}, MotionNormalsWindow{}, nullptr);
  // A window holding the first four of the six steps (keys 3, 5, 7 are steps 3..9 in twos:
  // the window is contiguous, so it holds steps 3..6 and the pass draws the rest itself).
  parallel::ParticleKernel kernel({2, 16});
  MotionNormalsAhead drawer(kernel, kSeed, 0);
  drawer.start_next(2, 3, m);  // steps 3, 4, 5, 6
  drawer.start_next(100, 0, m);
  advance<BaileyCarModel, false>(motion, ahead, {0, m}, drawer.ready(), nullptr);
  for (std::size_t i = 0; i < m; ++i) {
    EXPECT_EQ(one.store.x()[i], split.store.x()[i]);
    EXPECT_EQ(one.store.theta()[i], split.store.theta()[i]);
    EXPECT_EQ(one.store.x()[i], ahead.store.x()[i]);
    EXPECT_EQ(one.store.y()[i], ahead.store.y()[i]);
  }
}

// Lane l of a window is particle first + l of the set (a rank's share starts at `first`).
class MotionNormalsAheadTest : public ::testing::TestWithParam<std::uint32_t> {};

TEST_P(MotionNormalsAheadTest, WindowCopiesTheKeyedNormals) {
  const std::uint32_t first = GetParam();
  parallel::ParticleKernel kernel({2, 16});
  MotionNormalsAhead drawer(kernel, kSeed, first);
  EXPECT_TRUE(drawer.ready().keys.empty());
  drawer.start_next(9, 2, 20);  // draws steps 10, 11, 12
  drawer.start_next(50, 0, 20);
  const MotionNormalsWindow& w = drawer.ready();
  ASSERT_EQ(w.keys.size(), 3u);
  const std::vector<std::uint64_t> steps = {11, 12, 13};
  std::vector<double> out(2 * steps.size() * 8);
  EXPECT_EQ(w.copy(steps, 8, 8, out), 2u);  // step 13 is past the window
  for (std::size_t j = 0; j < 2; ++j) {
    for (std::size_t l = 0; l < 8; ++l) {
      double n[2];
      parallel::normal_pairs_for_particles(kSeed, steps[j], parallel::Purpose::kMotion,
                                           first + static_cast<std::uint32_t>(8 + l), 1, {&n[0], 1},
                                           {&n[1], 1});
      EXPECT_EQ(out[2 * j * 8 + l], n[0]);
      EXPECT_EQ(out[(2 * j + 1) * 8 + l], n[1]);
    }
  }
  EXPECT_EQ(w.copy(std::vector<std::uint64_t>{9}, 0, 8, out), 0u);
  EXPECT_EQ(w.copy(steps, 16, 16, out), 0u);  // beyond the window's lanes
}

INSTANTIATE_TEST_SUITE_P(FirstParticles, MotionNormalsAheadTest, ::testing::Values(0u, 768u));

}  // namespace
}  // namespace fastslam::engine::internal
