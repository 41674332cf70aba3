#include "engine/lg_slam_filter.h"

#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <vector>

#include <Eigen/Core>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include "engine/lg_slam.h"
#include "engine/proposal.h"
#include "parallel/random_stream.h"
#include "tests/engine/test_util.h"
#include "tools/studies/lg_slam_experiment.h"

namespace fastslam::engine {
namespace {

using testing::matrices_near;
using tools::LgSlamErrors;
using tools::LgSlamSimulator;
using tools::LgSlamVariant;
using tools::LgSlamWorldConfig;

// ---- The oracle: the Kalman filter of the joint Gaussian over (pose, landmarks).
// Linear models, so it is the exact posterior. A landmark enters the state at its first
// observation with a flat prior, which conditions exactly to m = s + z, Cov(m, .) = Cov(s, .),
// Var(m) = Var(s) + R. Dense and fixed-size (at most kMaxLandmarks landmarks; the slots of
// landmarks not in the state are zero and stay zero).
constexpr int kMaxLandmarks = 6;
constexpr int kMaxDim = 2 + 2 * kMaxLandmarks;
using StateVector = Eigen::Matrix<double, kMaxDim, 1>;
using StateMatrix = Eigen::Matrix<double, kMaxDim, kMaxDim>;
using Gain = Eigen::Matrix<double, kMaxDim, 2>;

class JointKalman {
 public:
  // REQUIRES: landmarks <= kMaxLandmarks.
  JointKalman(int landmarks, const Eigen::Vector2d& start, const Eigen::Matrix2d& p,
              const Eigen::Matrix2d& r)
      : p_(p), r_(r), in_state_(static_cast<std::size_t>(landmarks)) {
    x_.setZero();
    c_.setZero();
    x_.head<2>() = start;
  }
  void set_known(int id, const Eigen::Vector2d& position) {
    x_.segment<2>(2 + 2 * id) = position;  // covariance rows stay zero
    in_state_[static_cast<std::size_t>(id)] = true;
  }
  void step(const Eigen::Vector2d& u, const std::vector<LgSlamObservation>& observations) {
    x_.head<2>() += u;
    c_.topLeftCorner<2, 2>() += p_;
    for (const LgSlamObservation& obs : observations) {
      const int m = 2 + 2 * static_cast<int>(obs.id);
      if (!in_state_[obs.id]) continue;
      // H = [-I at the pose, +I at the landmark]: C H^T and H C H^T by blocks.
      const Gain cht = c_.middleCols<2>(m) - c_.leftCols<2>();
      const Eigen::Matrix2d s = cht.middleRows<2>(m) - cht.topRows<2>() + r_;
      const Gain k = cht * s.inverse();
      const Eigen::Vector2d v = obs.z - (x_.segment<2>(m) - x_.head<2>());
      x_ += k * v;
      // Coefficient-wise product: GCC 12 misreports Eigen's AVX-512 GEMM as uninitialised.
      const Eigen::Matrix<double, 2, kMaxDim> skt = s * k.transpose();
      StateMatrix c = c_ - k.lazyProduct(skt);
      c_ = 0.5 * (c + c.transpose());
    }
    for (const LgSlamObservation& obs : observations) {
      if (in_state_[obs.id]) continue;
      const int m = 2 + 2 * static_cast<int>(obs.id);
      x_.segment<2>(m) = x_.head<2>() + obs.z;
      c_.middleRows<2>(m) = c_.topRows<2>();
      c_.middleCols<2>(m) = c_.leftCols<2>();
      c_.block<2, 2>(m, m) = c_.topLeftCorner<2, 2>() + r_;
      in_state_[obs.id] = true;
    }
  }
  Eigen::Vector2d pose_mean() const { return x_.head<2>(); }
  Eigen::Matrix2d pose_cov() const { return c_.topLeftCorner<2, 2>(); }
  Eigen::Vector2d landmark_mean(std::size_t id) const { return x_.segment<2>(2 + 2 * id); }
  Eigen::Matrix2d landmark_cov(std::size_t id) const {
    const int m = 2 + 2 * static_cast<int>(id);
    return c_.block<2, 2>(m, m);
  }

 private:
  Eigen::Matrix2d p_, r_;
  std::vector<bool> in_state_;
  StateVector x_;
  StateMatrix c_;
};

LgSlamConfig config_for(const LgSlamWorldConfig& world, std::size_t particles, std::uint64_t seed) {
  LgSlamConfig config;
  config.particles = particles;
  config.landmarks = world.landmarks;
  config.motion_cov = world.sigma_motion * world.sigma_motion * Eigen::Matrix2d::Identity();
  config.measurement_cov =
      world.sigma_measurement * world.sigma_measurement * Eigen::Matrix2d::Identity();
  config.seed = seed;
  return config;
}

// ---- The theorem (section 7): M = 1, FastSLAM 2.0, landmark 0 known.

struct ConvergenceSummary {
  double early_landmark = 0.0;  // mean over seeds at step kEarly
  double final_landmark = 0.0;  // mean over seeds at the last step
  double final_pose = 0.0;      // mean over seeds and the last 100 steps
};
constexpr std::uint64_t kSteps = 2000;
constexpr std::uint64_t kEarly = 20;
constexpr int kSeeds = 8;

// Mean errors of `run(seed, on_step)` over seeds 1..kSeeds.
template <class Run>
ConvergenceSummary summarise(Run&& run) {
  ConvergenceSummary out;
  for (int seed = 1; seed <= kSeeds; ++seed) {
    run(static_cast<std::uint64_t>(seed), [&](std::uint64_t t, const LgSlamErrors& e) {
      if (t == kEarly) out.early_landmark += e.landmark / kSeeds;
      if (t == kSteps) out.final_landmark += e.landmark / kSeeds;
      if (t > kSteps - 100) out.final_pose += e.pose / (100.0 * kSeeds);
    });
  }
  return out;
}

ConvergenceSummary run_filter(LgSlamProposal proposal) {
  return summarise([&](std::uint64_t seed, auto&& on_step) {
    tools::run_lg_slam(LgSlamWorldConfig{}, LgSlamVariant::kAnchored, seed, kSteps, 1, proposal,
                       on_step);
  });
}

// The bound. FastSLAM 2.0 on the default world (6 landmarks on a 10 m circle, 2-3 in view,
// sigma 0.1 m for motion and sensor), seeds 1..8: landmark RMS 0.13 m at step 20, 0.071 m at
// step 2000, pose 0.11 m; over 50 disjoint blocks of 8 seeds the step-2000 landmark mean is at
// most 0.106 m, the pose mean at most 0.13 m and the final / early ratio at most 0.64. FastSLAM
// 1.0's motion-only proposal lets the pose drift like a random walk (about 0.1 sqrt(t) m) and
// the map with it: metres by step 2000; the wrong-sign proposal diverges geometrically. (A
// proposal that doubles Q stays inside this bound, 0.114 m; the Kalman test below catches it.)
constexpr double kLandmarkBound = 0.15;  // m, mean landmark RMS at step 2000
constexpr double kPoseBound = 0.2;       // m, mean pose error over the last 100 steps
constexpr double kShrink = 0.75;         // final / early landmark error

::testing::AssertionResult meets_bound(const ConvergenceSummary& s) {
  if (s.final_landmark < kLandmarkBound && s.final_pose < kPoseBound &&
      s.final_landmark < kShrink * s.early_landmark) {
    return ::testing::AssertionSuccess();
  }
  return ::testing::AssertionFailure()
         << "landmark " << s.early_landmark << " m at step " << kEarly << ", " << s.final_landmark
         << " m at step " << kSteps << "; pose " << s.final_pose << " m";
}

TEST(LgSlamFilterTest, OneParticleConvergesWithAnAnchor) {
  const ConvergenceSummary fs2 = run_filter(LgSlamProposal::kFastSlam2);
  EXPECT_TRUE(meets_bound(fs2));
  std::printf("FastSLAM 2.0: landmark %.4f m (step %llu) -> %.4f m (step %llu), pose %.4f m\n",
              fs2.early_landmark, static_cast<unsigned long long>(kEarly), fs2.final_landmark,
              static_cast<unsigned long long>(kSteps), fs2.final_pose);
}

// The same bound fails for a proposal the theorem does not cover: FastSLAM 1.0's (the motion
// prior alone).
TEST(LgSlamFilterTest, MotionOnlyProposalMissesTheBound) {
  const ConvergenceSummary fs1 = run_filter(LgSlamProposal::kMotion);
  EXPECT_FALSE(meets_bound(fs1));
  EXPECT_GT(fs1.final_landmark, 10.0 * kLandmarkBound);
  EXPECT_GT(fs1.final_pose, 10.0 * kPoseBound);
}

// ... and for FastSLAM 2.0 with one defect, the refinement applied with the wrong sign
// (mu_s' = mu_s - K v), assembled here from the same pieces as LgSlamFilter::step.
TEST(LgSlamFilterTest, WrongSignProposalMissesTheBound) {
  const LgSlamWorldConfig world;
  const ConvergenceSummary wrong = summarise([&](std::uint64_t seed, auto&& on_step) {
    LgSlamSimulator sim(world, seed);
    const LgSlamConfig config = config_for(world, 1, seed);
    const LinearGaussianMeasurement g;
    Eigen::Vector2d pose = sim.pose();
    std::vector<LandmarkGaussian> map(world.landmarks);
    std::vector<bool> mapped(world.landmarks, false);
    map[0] = {sim.landmarks()[0], Eigen::Matrix2d::Zero()};
    mapped[0] = true;
    Eigen::Vector2d u;
    std::vector<LgSlamObservation> observations;
    for (std::uint64_t t = 1; t <= kSteps; ++t) {
      sim.step(u, observations);
      PoseGaussian<2> proposal{pose + u, config.motion_cov};
      for (const LgSlamObservation& obs : observations) {
        if (!mapped[obs.id]) continue;
        ProposalObservation<2> o =
            evaluate_proposal<2>(g, map[obs.id], proposal, obs.z, config.measurement_cov);
        o.innovation = -o.innovation;
        proposal = fold<2>(proposal, o);
      }
      parallel::RandomStream rng({seed, t, 0, parallel::Purpose::kProposal});
      const double normals[2] = {rng.normal(), rng.normal()};
      pose = sample_pose<2>(proposal, normals);
      double sum2 = 0.0;
      int counted = 0;
      for (const LgSlamObservation& obs : observations) {
        if (obs.id == 0) continue;
        if (!mapped[obs.id]) {
          map[obs.id] = initialize_landmark(g, pose, obs.z, config.measurement_cov);
          mapped[obs.id] = true;
        } else {
          update_landmark(g, map[obs.id], pose, obs.z, config.measurement_cov);
        }
      }
      for (std::size_t k = 1; k < world.landmarks; ++k) {
        if (!mapped[k]) continue;
        sum2 += (map[k].mean - sim.landmarks()[k]).squaredNorm();
        ++counted;
      }
      LgSlamErrors e;
      e.landmark = std::sqrt(sum2 / counted);
      e.pose = (pose - sim.pose()).norm();
      on_step(t, e);
    }
  });
  EXPECT_FALSE(meets_bound(wrong));
  // Each fold pushes the pose away from where the map puts it: the error grows geometrically
  // and overflows (inf, then NaN) long before step 2000.
  EXPECT_FALSE(wrong.final_landmark <= 10.0 * kLandmarkBound) << wrong.final_landmark;
  EXPECT_GT(wrong.early_landmark, 10.0 * kLandmarkBound);
}

// ---- Against the joint Kalman filter.

// Motion noise 0: every pose is known exactly, FastSLAM 2.0's proposal collapses to the
// prediction, and each landmark EKF is the Kalman filter's marginal (its landmarks are then
// uncorrelated): equal to rounding at every step, anchored and relative.
TEST(LgSlamFilterTest, KnownPoseLimitIsTheJointKalmanFilter) {
  LgSlamWorldConfig world;
  world.sigma_motion = 0.0;
  for (const bool anchored : {true, false}) {
    LgSlamSimulator sim(world, 3);
    LgSlamFilter filter(config_for(world, 1, 3), sim.pose());
    JointKalman kf(static_cast<int>(world.landmarks), sim.pose(), filter.config().motion_cov,
                   filter.config().measurement_cov);
    if (anchored) {
      filter.set_known_landmark(0, sim.landmarks()[0]);
      kf.set_known(0, sim.landmarks()[0]);
    }
    Eigen::Vector2d u;
    std::vector<LgSlamObservation> observations;
    for (int t = 1; t <= 100; ++t) {
      sim.step(u, observations);
      filter.step(u, observations);
      kf.step(u, observations);
      ASSERT_TRUE(matrices_near(filter.pose(0), kf.pose_mean(), 1e-12, 1e-12)) << "step " << t;
      for (std::size_t k = 0; k < world.landmarks; ++k) {
        if (!filter.mapped(k)) continue;
        ASSERT_TRUE(matrices_near(filter.landmark(0, k).mean, kf.landmark_mean(k), 1e-11, 1e-12))
            << "step " << t << " landmark " << k;
        ASSERT_TRUE(matrices_near(filter.landmark(0, k).cov, kf.landmark_cov(k), 1e-15, 1e-9))
            << "step " << t << " landmark " << k;
      }
    }
  }
}

// With motion noise, FastSLAM 2.0 with its weights and resampling is a particle approximation of
// the same posterior: over replicate runs (filter seeds; the data fixed), the particle estimates
// of the pose and landmark means agree with the Kalman filter's within 5 standard errors of the
// replicate mean (plus 2% of the posterior's standard deviation for the O(1/M) bias of the
// particle approximation), and the particle covariances (mean of the landmark EKFs plus the
// spread of their means) within 10% of their variances. A wrong sign or covariance in the proposal
// or the weights moves these by many standard errors.
TEST(LgSlamFilterTest, ManyParticlesAgreeWithTheJointKalmanFilter) {
  LgSlamWorldConfig world;
  world.landmarks = 3;
  world.steps_per_loop = 6;
  world.sigma_motion = 0.3;
  constexpr int kTinySteps = 8;
  constexpr std::size_t kParticles = 2000;
  constexpr int kReplicates = 20;
  for (const bool anchored : {true, false}) {
    LgSlamSimulator sim(world, 11);
    std::vector<Eigen::Vector2d> controls;
    std::vector<std::vector<LgSlamObservation>> scans;
    const Eigen::Vector2d start = sim.pose();
    for (int t = 0; t < kTinySteps; ++t) {
      controls.emplace_back();
      scans.emplace_back();
      sim.step(controls.back(), scans.back());
    }
    const LgSlamConfig base = config_for(world, kParticles, 0);
    JointKalman kf(3, start, base.motion_cov, base.measurement_cov);
    if (anchored) kf.set_known(0, sim.landmarks()[0]);
    for (int t = 0; t < kTinySteps; ++t) kf.step(controls[t], scans[t]);

    // Components: pose (0..1), landmark k (2k+2 .. 2k+3); first moments and covariances.
    constexpr int kComponents = 8;
    Eigen::Matrix<double, kComponents, 1> kf_mean, kf_sd, sum, sum2;
    std::vector<Eigen::Matrix2d> kf_cov(4), cov_sum(4, Eigen::Matrix2d::Zero());
    kf_mean.head<2>() = kf.pose_mean();
    kf_cov[0] = kf.pose_cov();
    for (std::size_t k = 0; k < 3; ++k) {
      kf_mean.segment<2>(2 + 2 * k) = kf.landmark_mean(k);
      kf_cov[k + 1] = kf.landmark_cov(k);
    }
    for (int b = 0; b < 4; ++b) {
      kf_sd.segment<2>(2 * b) = kf_cov[b].diagonal().cwiseSqrt();
    }
    sum.setZero();
    sum2.setZero();
    for (int r = 0; r < kReplicates; ++r) {
      LgSlamConfig config = base;
      config.seed = 1000 + static_cast<std::uint64_t>(r);
      LgSlamFilter filter(config, start);
      if (anchored) filter.set_known_landmark(0, sim.landmarks()[0]);
      for (int t = 0; t < kTinySteps; ++t) filter.step(controls[t], scans[t]);
      ASSERT_TRUE(filter.mapped(1) && filter.mapped(2));
      // After resampling the weights are uniform: plain particle averages.
      Eigen::Matrix<double, kComponents, 1> est;
      est.head<2>() = filter.mean_pose();
      for (std::size_t k = 0; k < 3; ++k) est.segment<2>(2 + 2 * k) = filter.mean_landmark(k);
      sum += est;
      sum2 += est.cwiseAbs2();
      for (std::size_t i = 0; i < kParticles; ++i) {
        const Eigen::Vector2d dp = filter.pose(i) - est.head<2>();
        cov_sum[0] += dp * dp.transpose() / (kParticles * kReplicates);
        for (std::size_t k = 0; k < 3; ++k) {
          const Eigen::Vector2d dm = filter.landmark(i, k).mean - est.segment<2>(2 + 2 * k);
          cov_sum[k + 1] +=
              (filter.landmark(i, k).cov + dm * dm.transpose()) / (kParticles * kReplicates);
        }
      }
    }
    const Eigen::Matrix<double, kComponents, 1> mean = sum / kReplicates;
    for (int c = 0; c < kComponents; ++c) {
      if (anchored && (c == 2 || c == 3)) {
        EXPECT_NEAR(mean[c], kf_mean[c], 1e-12);  // the known landmark is never changed
        continue;
      }
      const double var = (sum2[c] - kReplicates * mean[c] * mean[c]) / (kReplicates - 1);
      const double se = std::sqrt(std::max(var, 0.0) / kReplicates);
      EXPECT_LE(std::abs(mean[c] - kf_mean[c]), 5.0 * se + 0.02 * kf_sd[c])
          << (anchored ? "anchored" : "relative") << " component " << c << ": particles " << mean[c]
          << ", Kalman " << kf_mean[c] << ", standard error " << se << ", posterior sd "
          << kf_sd[c];
    }
    for (int b = 0; b < 4; ++b) {
      if (anchored && b == 1) continue;
      EXPECT_TRUE(matrices_near(cov_sum[b], kf_cov[b], 0.10 * kf_cov[b].trace() / 2, 0.0))
          << (anchored ? "anchored" : "relative") << " block " << b;
    }
  }
}

// ---- Determinism, the anchor, and refusals.

TEST(LgSlamFilterTest, SameSeedSameResultOtherSeedOtherResult) {
  const LgSlamWorldConfig world;
  auto run = [&](std::uint64_t seed) {
    LgSlamSimulator sim(world, 5);
    LgSlamFilter filter(config_for(world, 3, seed), sim.pose());
    Eigen::Vector2d u;
    std::vector<LgSlamObservation> observations;
    for (int t = 0; t < 50; ++t) {
      sim.step(u, observations);
      filter.step(u, observations);
    }
    std::vector<double> out;
    for (std::size_t i = 0; i < filter.particles(); ++i) {
      out.push_back(filter.pose(i)[0]);
      out.push_back(filter.landmark(i, 1).mean[1]);
    }
    return out;
  };
  EXPECT_EQ(run(1), run(1));
  EXPECT_NE(run(1), run(2));
}

TEST(LgSlamFilterTest, KnownLandmarkIsNeverChanged) {
  const LgSlamWorldConfig world;
  LgSlamSimulator sim(world, 9);
  LgSlamFilter filter(config_for(world, 4, 9), sim.pose());
  const Eigen::Vector2d anchor(10.5, -0.25);  // not the truth: still never moved
  filter.set_known_landmark(0, anchor);
  Eigen::Vector2d u;
  std::vector<LgSlamObservation> observations;
  int seen = 0;
  for (int t = 0; t < 40; ++t) {
    sim.step(u, observations);
    for (const LgSlamObservation& o : observations) seen += o.id == 0 ? 1 : 0;
    filter.step(u, observations);
    for (std::size_t i = 0; i < filter.particles(); ++i) {
      ASSERT_EQ(filter.landmark(i, 0).mean, anchor);
      ASSERT_EQ(filter.landmark(i, 0).cov, Eigen::Matrix2d::Zero());
    }
  }
  EXPECT_GT(seen, 5);
  EXPECT_TRUE(filter.known(0));
  EXPECT_FALSE(filter.known(1));
}

TEST(LgSlamFilterTest, RefusesBadConfigAndInputAndChangesNothing) {
  LgSlamConfig config;
  config.landmarks = 3;
  const Eigen::Vector2d start(1.0, 2.0);
  {
    LgSlamConfig bad = config;
    bad.particles = 0;
    EXPECT_THROW(LgSlamFilter(bad, start), std::invalid_argument);
    bad = config;
    bad.landmarks = 0;
    EXPECT_THROW(LgSlamFilter(bad, start), std::invalid_argument);
    bad = config;
    bad.motion_cov(0, 0) = -1.0;
    EXPECT_THROW(LgSlamFilter(bad, start), std::invalid_argument);
    bad = config;
    bad.motion_cov.setZero();  // a noise-free motion is fine
    EXPECT_NO_THROW(LgSlamFilter(bad, start));
    bad = config;
    bad.measurement_cov.setZero();
    EXPECT_THROW(LgSlamFilter(bad, start), std::invalid_argument);
    EXPECT_THROW(LgSlamFilter(config, Eigen::Vector2d(std::nan(""), 0.0)), std::invalid_argument);
  }
  LgSlamFilter filter(config, start);
  EXPECT_THROW(filter.set_known_landmark(3, start), std::invalid_argument);
  filter.step(Eigen::Vector2d(0.5, 0.0), std::vector<LgSlamObservation>{{1, {2.0, 0.0}}});
  EXPECT_THROW(filter.set_known_landmark(1, start), std::invalid_argument);  // already mapped
  const Eigen::Vector2d pose = filter.pose(0);
  const LandmarkGaussian lm = filter.landmark(0, 1);
  const double inf = std::numeric_limits<double>::infinity();
  const std::vector<std::vector<LgSlamObservation>> bad_scans = {
      {{0, {1.0, 1.0}}, {3, {1.0, 1.0}}},  // id out of range
      {{1, {1.0, 1.0}}, {1, {1.1, 1.0}}},  // the same landmark twice
      {{2, {inf, 1.0}}}};                  // not finite
  for (const auto& scan : bad_scans) {
    try {
      filter.step(Eigen::Vector2d(0.5, 0.0), scan);
      ADD_FAILURE() << "no throw";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("observation"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(filter.step(Eigen::Vector2d(inf, 0.0), {}), std::invalid_argument);
  EXPECT_EQ(filter.steps(), 1u);
  EXPECT_EQ(filter.pose(0), pose);
  EXPECT_EQ(filter.landmark(0, 1).mean, lm.mean);
  EXPECT_FALSE(filter.mapped(0));
  EXPECT_FALSE(filter.mapped(2));
}

}  // namespace
}  // namespace fastslam::engine
