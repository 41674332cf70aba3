#include "engine/proposal.h"

#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include "engine/landmark_ekf.h"
#include "engine/measurement_model.h"
#include "engine/motion_model.h"
#include "tests/engine/test_util.h"

namespace fastslam::engine {
namespace {

using testing::matrices_near;
using testing::numeric_jacobian;
using testing::random_heading;

// Oracles invert in long double: Eigen has no SIMD path for it, so these dense inversions are an
// independent computation (and GCC 12 raises no false AVX-512 warnings in them).
template <int N>
using MatrixL = Eigen::Matrix<long double, N, N>;

template <int N>
Eigen::Matrix<double, N, N> random_spd(std::mt19937_64& rng, double scale) {
  std::normal_distribution<double> n;
  Eigen::Matrix<double, N, N> a;
  for (int i = 0; i < N; ++i) {
    for (int j = 0; j < N; ++j) {
      a(i, j) = n(rng);
    }
  }
  Eigen::Matrix<double, N, N> m = scale * scale * (a * a.transpose() / N);
  m.diagonal().array() += 0.05 * scale * scale;
  return 0.5 * (m + m.transpose());
}

// eq. 48-49 written literally (information form, needs P invertible), for comparison with the
// Kalman form of `fold`: Q = R + G_mu Sigma G_mu^T, Sigma_s = (G_s^T Q^-1 G_s + P^-1)^-1,
// mu_s = Sigma_s G_s^T Q^-1 (z - z_hat) + s_hat.
template <int N>
PoseGaussian<N> literal_eq_48_49(const MeasurementLinearization<N>& lin, const Eigen::Vector2d& v,
                                 const Eigen::Matrix2d& landmark_cov, const PoseGaussian<N>& prior,
                                 const Eigen::Matrix2d& r) {
  const Eigen::Matrix<long double, 2, N> gs = lin.g_pose.template cast<long double>();
  const MatrixL<2> gm = lin.g_landmark.template cast<long double>();
  const MatrixL<2> q =
      r.cast<long double>() + gm * landmark_cov.cast<long double>() * gm.transpose();
  const MatrixL<2> q_inv = q.inverse();
  const MatrixL<N> p_inv = prior.cov.template cast<long double>().inverse();
  const MatrixL<N> sigma = (gs.transpose() * q_inv * gs + p_inv).inverse();
  PoseGaussian<N> out;
  out.cov = sigma.template cast<double>();
  out.mean =
      (sigma * gs.transpose() * q_inv * v.cast<long double>()).template cast<double>() + prior.mean;
  return out;
}

TEST(ProposalTest, KalmanFormEqualsEquations48And49) {
  std::mt19937_64 rng(31);
  std::uniform_real_distribution<double> pos(-50.0, 50.0);
  std::uniform_real_distribution<double> range(2.0, 40.0);
  std::normal_distribution<double> n;
  const RangeBearingModel model(SensorOffset{3.78, 0.5, 0.0});
  for (int i = 0; i < 2000; ++i) {
    PoseGaussian<3> prior;
    prior.mean << pos(rng), pos(rng), random_heading(rng);
    prior.cov = random_spd<3>(rng, 0.2);
    LandmarkGaussian lm;
    lm.mean = model.landmark_from({range(rng), random_heading(rng)}, prior.mean);
    lm.cov = random_spd<2>(rng, 0.5);
    Eigen::Matrix2d r;
    r << 0.01, 0.0, 0.0, 1e-4;
    Eigen::Vector2d z =
        model.predict(lm.mean, prior.mean) + Eigen::Vector2d(0.2 * n(rng), 0.02 * n(rng));
    z[1] = wrap_angle(z[1]);
    const ProposalObservation<3> obs = evaluate_proposal<3>(model, lm, prior, z, r);
    const PoseGaussian<3> folded = fold<3>(prior, obs);
    const auto lin = model.linearize(lm.mean, prior.mean);
    const PoseGaussian<3> expected =
        literal_eq_48_49<3>(lin, RangeBearingModel::innovation(z, lin.z_hat), lm.cov, prior, r);
    const double scale = std::sqrt(expected.cov.diagonal().maxCoeff());
    ASSERT_TRUE(matrices_near(folded.cov, expected.cov, 1e-12 * scale * scale, 1e-7))
        << "case " << i;
    Eigen::Vector3d diff = folded.mean - expected.mean;
    diff[2] = wrap_angle(diff[2]);
    ASSERT_LT(diff.norm(), 1e-9 * (1.0 + scale)) << "case " << i;
    ASSERT_GT(folded.mean[2], -kPi);
    ASSERT_LE(folded.mean[2], kPi);
    ASSERT_EQ(folded.cov, folded.cov.transpose());
  }
}

// The same for the 5-D no-odometry state: the velocities are corrected through their
// correlation with the pose, although G_s has zero columns for them.
TEST(ProposalTest, FiveDimensionalStateEqualsEquations48And49) {
  std::mt19937_64 rng(32);
  const RangeBearingModel model;
  for (int i = 0; i < 500; ++i) {
    PoseGaussian<5> prior;
    prior.mean << 1.0, -2.0, random_heading(rng), 3.0, 0.1;
    prior.cov = random_spd<5>(rng, 0.3);
    LandmarkGaussian lm;
    lm.mean = model.landmark_from({12.0, 0.4}, prior.mean.head<3>().eval());
    lm.cov = random_spd<2>(rng, 0.3);
    Eigen::Matrix2d r;
    r << 0.04, 0.0, 0.0, 4e-4;
    const Eigen::Vector2d z(12.3, wrap_angle(0.38));
    const PoseGaussian<5> folded = fold_observation<5>(model, prior, lm, z, r);
    const auto lin = model.linearize_state<5>(lm.mean, prior.mean);
    const PoseGaussian<5> expected =
        literal_eq_48_49<5>(lin, RangeBearingModel::innovation(z, lin.z_hat), lm.cov, prior, r);
    ASSERT_TRUE(matrices_near(folded.cov, expected.cov, 1e-12, 1e-7)) << "case " << i;
    Eigen::Matrix<double, 5, 1> diff = folded.mean - expected.mean;
    diff[2] = wrap_angle(diff[2]);
    ASSERT_LT(diff.norm(), 1e-9) << "case " << i;
    ASSERT_GT((folded.mean.tail<2>() - prior.mean.tail<2>()).norm(), 0.0);
  }
}

// The posterior p(s | z_1..z_k, prior) computed by brute force on a 3-D grid of poses, with
// p(z | s) = N(z; g(mu, s), R + G_mu Sigma G_mu^T) evaluated exactly in s at every grid point,
// and the prior N(s_hat, P). Returns the mean (heading relative to s_hat, wrapped) and covariance.
struct GridMoments {
  Eigen::Vector3d mean;
  Eigen::Matrix3d cov;
};
GridMoments grid_posterior(const RangeBearingModel& model, const PoseGaussian<3>& prior,
                           const std::vector<LandmarkGaussian>& lms,
                           const std::vector<Eigen::Vector2d>& zs, const Eigen::Matrix2d& r,
                           int points_per_axis, double half_width_sds) {
  const Eigen::Matrix3d p_inv = prior.cov.inverse();
  Eigen::Vector3d half;
  for (int i = 0; i < 3; ++i) {
    half[i] = half_width_sds * std::sqrt(prior.cov(i, i));
  }
  const int n = points_per_axis;
  std::vector<double> log_p;
  std::vector<Eigen::Vector3d> offsets;
  log_p.reserve(static_cast<std::size_t>(n) * n * n);
  offsets.reserve(log_p.capacity());
  double max_log = -1e300;
  for (int a = 0; a < n; ++a) {
    for (int b = 0; b < n; ++b) {
      for (int c = 0; c < n; ++c) {
        const Eigen::Vector3d d(-half[0] + 2.0 * half[0] * a / (n - 1),
                                -half[1] + 2.0 * half[1] * b / (n - 1),
                                -half[2] + 2.0 * half[2] * c / (n - 1));
        Pose s = prior.mean + d;
        s[2] = wrap_angle(s[2]);
        double lp = -0.5 * d.dot(p_inv * d);
        for (std::size_t k = 0; k < lms.size(); ++k) {
          const auto lin = model.linearize(lms[k].mean, s);
          const Eigen::Matrix2d q = lin.g_landmark * lms[k].cov * lin.g_landmark.transpose() + r;
          const Eigen::Vector2d v = RangeBearingModel::innovation(zs[k], lin.z_hat);
          lp += -0.5 * v.dot(q.inverse() * v) - 0.5 * std::log(q.determinant());
        }
        log_p.push_back(lp);
        offsets.push_back(d);
        max_log = std::max(max_log, lp);
      }
    }
  }
  double total = 0.0;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d sum_sq = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < log_p.size(); ++i) {
    const double w = std::exp(log_p[i] - max_log);
    total += w;
    sum += w * offsets[i];
    sum_sq += w * offsets[i] * offsets[i].transpose();
  }
  GridMoments m;
  m.mean = sum / total;
  m.cov = sum_sq / total - m.mean * m.mean.transpose();
  return m;
}

// Tolerances: the proposal linearises g in s, so it errs by the second-order terms over the
// posterior's spread. With pose spreads delta of a few cm at ranges r of 6-10 m these are
// delta^2 / r (range) and delta^2 / r^2 (bearing): about 1 % of the measurement noise here, so
// moments should agree to a few percent of a posterior standard deviation; we allow 3 % (the
// largest deviation seen is 0.9 %). The grid spans +-6 prior sds (the posterior is narrower than
// the prior) in 61 points per axis (0.2 prior sds apart); with 81 points no compared moment moved
// by 1e-4 sd, so the grid is not what limits the agreement.
void expect_matches_grid(const RangeBearingModel& model, const PoseGaussian<3>& prior,
                         const std::vector<LandmarkGaussian>& lms,
                         const std::vector<Eigen::Vector2d>& zs, const Eigen::Matrix2d& r) {
  PoseGaussian<3> proposal = prior;
  for (std::size_t k = 0; k < lms.size(); ++k) {
    proposal = fold_observation<3>(model, proposal, lms[k], zs[k], r);
  }
  const GridMoments grid = grid_posterior(model, prior, lms, zs, r, 61, 6.0);
  Eigen::Vector3d mean = proposal.mean - prior.mean;
  mean[2] = wrap_angle(mean[2]);
  // The posterior should differ from the prior, or the test shows nothing.
  ASSERT_GT((grid.mean.array().abs() / prior.cov.diagonal().array().sqrt()).maxCoeff(), 0.3);
  ASSERT_LT(grid.cov.determinant(), 0.5 * prior.cov.determinant());
  for (int i = 0; i < 3; ++i) {
    const double sd = std::sqrt(grid.cov(i, i));
    EXPECT_NEAR(mean[i], grid.mean[i], 0.03 * sd) << "mean component " << i;
    for (int j = 0; j < 3; ++j) {
      EXPECT_NEAR(proposal.cov(i, j), grid.cov(i, j),
                  0.03 * std::sqrt(grid.cov(i, i) * grid.cov(j, j)))
          << "covariance (" << i << ", " << j << ")";
    }
  }
}

PoseGaussian<3> small_prior(double heading) {
  PoseGaussian<3> prior;
  prior.mean << 10.0, -4.0, heading;
  prior.cov << 4e-4, 1e-4, 2e-5,  //
      1e-4, 9e-4, -1e-5,          //
      2e-5, -1e-5, 1.6e-5;        // 2 cm, 3 cm, 0.23 deg
  return prior;
}

Eigen::Matrix2d small_r() {
  Eigen::Matrix2d r;
  r << 1e-4, 0.0, 0.0, 4e-6;  // 1 cm, 0.11 deg
  return r;
}

TEST(ProposalTest, OneLandmarkMatchesTheGridPosterior) {
  const RangeBearingModel model;
  // The heading on the seam: grid poses and the proposal mean both cross +-pi.
  const PoseGaussian<3> prior = small_prior(kPi - 0.002);
  // The observation was made from a pose away from s_hat, so the posterior mean moves.
  const Pose truth = prior.mean + Eigen::Vector3d(0.02, -0.03, 0.003);
  LandmarkGaussian lm;
  lm.mean = model.landmark_from({8.0, 0.7}, prior.mean);
  lm.cov = 1e-5 * Eigen::Matrix2d::Identity();
  const Eigen::Vector2d z = model.predict(lm.mean, truth);
  expect_matches_grid(model, prior, {lm}, {z}, small_r());
}

TEST(ProposalTest, OneLandmarkWithSensorOffsetMatchesTheGridPosterior) {
  const RangeBearingModel model(SensorOffset{3.78, 0.5, 0.0});
  const PoseGaussian<3> prior = small_prior(-kPi + 0.001);
  const Pose truth = prior.mean + Eigen::Vector3d(-0.01, 0.04, -0.004);
  LandmarkGaussian lm;
  lm.mean = model.landmark_from({6.0, -1.2}, prior.mean);
  lm.cov = 1e-5 * Eigen::Matrix2d::Identity();
  const Eigen::Vector2d z = model.predict(lm.mean, truth);
  expect_matches_grid(model, prior, {lm}, {z}, small_r());
}

// Two observations folded one after the other (each linearised at the refined mean) against the
// grid posterior of both.
TEST(ProposalTest, TwoFoldedLandmarksMatchTheGridPosterior) {
  const RangeBearingModel model;
  const PoseGaussian<3> prior = small_prior(0.4);
  const Pose truth = prior.mean + Eigen::Vector3d(0.03, 0.02, -0.004);
  std::vector<LandmarkGaussian> lms(2);
  lms[0].mean = model.landmark_from({9.0, 0.5}, prior.mean);
  lms[0].cov = 1e-5 * Eigen::Matrix2d::Identity();
  lms[1].mean = model.landmark_from({7.0, -1.4}, prior.mean);
  lms[1].cov << 2e-5, 5e-6, 5e-6, 1e-5;
  const std::vector<Eigen::Vector2d> zs = {model.predict(lms[0].mean, truth),
                                           model.predict(lms[1].mean, truth)};
  expect_matches_grid(model, prior, lms, zs, small_r());
}

// The weight term against eq. 60-61 built independently: Jacobians by central differences at
// s_hat, L = G_s P G_s^T + G_mu Sigma G_mu^T + R, w = |2 pi L|^-1/2 exp(-1/2 v^T L^-1 v).
TEST(ProposalTest, LogWeightIsEquations60And61) {
  std::mt19937_64 rng(33);
  std::uniform_real_distribution<double> pos(-50.0, 50.0);
  std::uniform_real_distribution<double> range(2.0, 40.0);
  std::normal_distribution<double> n;
  const BaileyCarModel car(4.0);
  for (const SensorOffset& offset : {SensorOffset{}, SensorOffset{3.78, 0.5, 0.1}}) {
    const RangeBearingModel model(offset);
    for (int i = 0; i < 1000; ++i) {
      const Pose previous(pos(rng), pos(rng), random_heading(rng));
      const Eigen::Vector2d u(3.0, 0.3 * n(rng));
      PoseGaussian<3> motion;
      motion.mean = car.predict(previous, u, 0.2);
      motion.cov =
          car.pose_noise(previous, u, 0.2, BaileyCarModel::control_covariance({0.3, 0.05}));
      LandmarkGaussian lm;
      lm.mean = model.landmark_from({range(rng), random_heading(rng)}, motion.mean);
      lm.cov = random_spd<2>(rng, 0.3);
      Eigen::Matrix2d r;
      r << 0.01, 0.0, 0.0, 3e-4;
      Eigen::Vector2d z =
          model.predict(lm.mean, motion.mean) + Eigen::Vector2d(0.2 * n(rng), 0.03 * n(rng));
      z[1] = wrap_angle(z[1]);

      const std::array<bool, 2> bearing = {false, true};
      const Eigen::Matrix<double, 2, 3> g_s = numeric_jacobian<2, 3>(
          [&](const Eigen::Vector3d& s) { return model.predict(lm.mean, s); }, motion.mean,
          bearing);
      const Eigen::Matrix2d g_mu = numeric_jacobian<2, 2>(
          [&](const Eigen::Vector2d& m) { return model.predict(m, motion.mean); }, lm.mean,
          bearing);
      const Eigen::Matrix2d l =
          g_s * motion.cov * g_s.transpose() + g_mu * lm.cov * g_mu.transpose() + r;
      const Eigen::Vector2d z_hat = model.predict(lm.mean, motion.mean);
      const Eigen::Vector2d v(z[0] - z_hat[0], wrap_angle(z[1] - z_hat[1]));
      const double w =
          std::pow((2.0 * kPi * l).determinant(), -0.5) * std::exp(-0.5 * v.dot(l.inverse() * v));
      const double got = log_weight<3>(model, lm, motion, z, r);
      ASSERT_NEAR(got, std::log(w), 1e-6 * std::max(1.0, std::abs(std::log(w)))) << "case " << i;
    }
  }
}

// The weight differs from the FastSLAM 1.0 likelihood exactly by the pose term G_s P G_s^T.
TEST(ProposalTest, ObservationTermsAreConsistentWithTheLandmarkEkf) {
  const RangeBearingModel model;
  PoseGaussian<3> motion = small_prior(1.0);
  LandmarkGaussian lm;
  lm.mean = model.landmark_from({10.0, 0.3}, motion.mean);
  lm.cov << 0.04, 0.01, 0.01, 0.02;
  const Eigen::Vector2d z(10.2, 0.31);
  const Eigen::Matrix2d r = small_r();
  const ProposalObservation<3> p = evaluate_proposal<3>(model, lm, motion, z, r);
  const LandmarkObservation e = evaluate_observation(model, lm, Pose(motion.mean), z, r);
  EXPECT_TRUE(matrices_near(p.q, e.q, 0.0, 1e-14));
  EXPECT_TRUE(
      matrices_near(p.l, (e.q + p.g_pose * motion.cov * p.g_pose.transpose()).eval(), 0.0, 1e-14));
  motion.cov.setZero();  // a certain pose: L = Q and the weight is eq. 31
  EXPECT_NEAR(log_weight<3>(model, lm, motion, z, r), e.log_likelihood, 1e-12);
  // Evaluating changes nothing; folding with a zero pose covariance leaves the pose.
  const ProposalObservation<3> again = evaluate_proposal<3>(model, lm, motion, z, r);
  const PoseGaussian<3> folded = fold<3>(motion, again);
  EXPECT_TRUE(matrices_near(folded.mean, motion.mean, 1e-15, 0.0));
  EXPECT_TRUE(folded.cov.isZero(0.0));
}

// scale_weight moves only the likelihood, to ln N(v; 0, L + (k - 1) R) (a closed-form density,
// oracle), and leaves the proposal's terms and its fold bit for bit; k = 1 gives the plain
// likelihood back; weight_scale(rho) = (1 + rho) / (1 - rho).
TEST(ProposalTest, WeightScaleWidensOnlyTheLikelihood) {
  EXPECT_EQ(weight_scale(0.0), 1.0);
  EXPECT_DOUBLE_EQ(weight_scale(0.5), 3.0);
  EXPECT_DOUBLE_EQ(weight_scale(0.89), 1.89 / 0.11);
  const RangeBearingModel model;
  const PoseGaussian<3> motion = small_prior(1.0);
  LandmarkGaussian lm;
  lm.mean = model.landmark_from({10.0, 0.3}, motion.mean);
  lm.cov << 0.04, 0.01, 0.01, 0.02;
  const Eigen::Vector2d z(10.4, 0.33);
  const Eigen::Matrix2d r = small_r();
  const ProposalObservation<3> plain = evaluate_proposal<3>(model, lm, motion, z, r);
  ProposalObservation<3> one = plain;
  scale_weight<3>(one, r, 1.0);
  EXPECT_NEAR(one.log_likelihood, plain.log_likelihood, 1e-13);
  for (const double k : {2.0, 17.2}) {
    SCOPED_TRACE(k);
    ProposalObservation<3> w = plain;
    scale_weight<3>(w, r, k);
    const Eigen::Matrix2d lw = plain.l + (k - 1.0) * r;
    const Eigen::Vector2d& v = plain.innovation;
    const double expected =
        -0.5 * std::log((2.0 * kPi * lw).determinant()) - 0.5 * v.dot(lw.inverse() * v);
    EXPECT_NEAR(w.log_likelihood, expected, 1e-12 * std::max(1.0, std::abs(expected)));
    EXPECT_NE(w.log_likelihood, plain.log_likelihood);
    EXPECT_EQ(w.mahalanobis2, plain.mahalanobis2);  // the gate's distance is the proposal's
    EXPECT_TRUE(matrices_near(w.l, plain.l, 0.0, 0.0));
    const PoseGaussian<3> a = fold<3>(motion, w);
    const PoseGaussian<3> b = fold<3>(motion, plain);
    EXPECT_TRUE(matrices_near(a.mean, b.mean, 0.0, 0.0));
    EXPECT_TRUE(matrices_near(a.cov, b.cov, 0.0, 0.0));
  }
}

TEST(PsdFactorTest, ReproducesFullAndRankDeficientMatrices) {
  std::mt19937_64 rng(34);
  const BaileyCarModel car(4.0);
  for (int i = 0; i < 1000; ++i) {
    const Eigen::Matrix3d full = random_spd<3>(rng, 0.5);
    const Eigen::Matrix3d f = psd_factor<3>(full);
    ASSERT_TRUE(f.isLowerTriangular(0.0));
    ASSERT_TRUE(matrices_near((f * f.transpose()).eval(), full, 1e-15, 1e-12));
    ASSERT_TRUE(matrices_near(f, Eigen::Matrix3d(full.llt().matrixL()), 1e-15, 1e-12));
    // P = V M V^T of the car is rank 2.
    const Pose s(0.0, 0.0, random_heading(rng));
    const Eigen::Matrix3d p =
        car.pose_noise(s, {3.0, 0.2}, 0.025, BaileyCarModel::control_covariance({0.3, 0.05}));
    const Eigen::Matrix3d fp = psd_factor<3>(p);
    ASSERT_TRUE(fp.allFinite());
    ASSERT_TRUE(
        matrices_near((fp * fp.transpose()).eval(), p, 1e-12 * p.diagonal().maxCoeff(), 1e-8))
        << p;
  }
  EXPECT_TRUE(psd_factor<3>(Eigen::Matrix3d::Zero()).isZero(0.0));
}

TEST(SamplePoseTest, ZeroNormalsGiveTheMean) {
  PoseGaussian<3> g = small_prior(kPi);
  const double zeros[3] = {0.0, 0.0, 0.0};
  EXPECT_EQ(sample_pose<3>(g, zeros), g.mean);
}

// Sample moments of many draws (a local std::mt19937_64 supplying the normals) against the
// Gaussian, heading on the seam; bounds as in motion_model_test (5 sds of the estimators).
TEST(SamplePoseTest, DrawsHaveTheProposalMoments) {
  const BaileyCarModel car(4.0);
  PoseGaussian<3> g;
  g.mean << 1.0, 2.0, kPi - 0.01;
  // A rank-2 motion covariance refined by one observation, the usual FastSLAM 2.0 case.
  g.cov = car.pose_noise(g.mean, {3.0, 0.2}, 0.5, BaileyCarModel::control_covariance({0.3, 0.05}));
  g.cov += 1e-4 * Eigen::Matrix3d::Identity();
  constexpr int kDraws = 200000;
  std::mt19937_64 rng(35);
  std::normal_distribution<double> normal;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  Eigen::Matrix3d sum_sq = Eigen::Matrix3d::Zero();
  for (int i = 0; i < kDraws; ++i) {
    const double n[3] = {normal(rng), normal(rng), normal(rng)};
    const Pose s = sample_pose<3>(g, n);
    ASSERT_GT(s[2], -kPi);
    ASSERT_LE(s[2], kPi);
    Eigen::Vector3d d = s - g.mean;
    d[2] = wrap_angle(d[2]);
    sum += d;
    sum_sq += d * d.transpose();
  }
  const Eigen::Vector3d mean = sum / kDraws;
  const Eigen::Matrix3d cov = sum_sq / kDraws - mean * mean.transpose();
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(mean[i], 0.0, 5.0 * std::sqrt(g.cov(i, i) / kDraws));
    for (int j = 0; j < 3; ++j) {
      const double sd = std::sqrt((g.cov(i, i) * g.cov(j, j) + g.cov(i, j) * g.cov(i, j)) / kDraws);
      EXPECT_NEAR(cov(i, j), g.cov(i, j), 5.0 * sd) << "(" << i << ", " << j << ")";
    }
  }
}

// draw_state on the pose-only state is sample_pose with nothing left over.
TEST(DrawStateTest, PoseOnlyStateIsSamplePose) {
  std::mt19937_64 rng(41);
  std::normal_distribution<double> normal;
  for (int trial = 0; trial < 50; ++trial) {
    PoseGaussian<3> g;
    g.mean << normal(rng), normal(rng), random_heading(rng);
    g.cov = random_spd<3>(rng, 0.3);
    const double n[3] = {normal(rng), normal(rng), normal(rng)};
    Eigen::Matrix3d rest = Eigen::Matrix3d::Constant(7.0);
    EXPECT_EQ(draw_state<3>(g, n, rest), sample_pose<3>(g, n));
    EXPECT_TRUE(rest.isZero(0.0));
  }
}

// The no-odometry state (x, y, theta, v, omega): the pose is sample_pose's, the velocities are
// the conditional mean given that pose and their covariance the conditional one (Schur
// complement), both against a dense long-double oracle; nothing else is left in the covariance.
TEST(DrawStateTest, VelocitiesKeepTheirGaussianGivenTheDrawnPose) {
  std::mt19937_64 rng(43);
  std::normal_distribution<double> normal;
  for (int trial = 0; trial < 200; ++trial) {
    PoseGaussian<5> g;
    g.mean << normal(rng), normal(rng), random_heading(rng), 3.0 * normal(rng), normal(rng);
    g.cov = random_spd<5>(rng, 0.2 + 0.1 * trial / 200.0);
    double n[5];
    for (double& v : n) v = normal(rng);
    Eigen::Matrix<double, 5, 5> rest;
    const Eigen::Matrix<double, 5, 1> s = draw_state<5>(g, n, rest);
    const Eigen::Matrix<double, 5, 1> full = sample_pose<5>(g, n);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(s[k], full[k], 1e-12) << k;
    // Oracle: mu_2 + S21 S11^-1 (p - mu_1) and S22 - S21 S11^-1 S12.
    const MatrixL<5> c = g.cov.cast<long double>();
    const Eigen::Matrix<long double, 3, 3> s11_inv = c.topLeftCorner<3, 3>().inverse();
    Eigen::Matrix<long double, 3, 1> dp;
    for (int k = 0; k < 3; ++k) dp[k] = static_cast<long double>(s[k]) - g.mean[k];
    dp[2] = static_cast<long double>(wrap_angle(static_cast<double>(dp[2])));
    const Eigen::Matrix<long double, 2, 1> mean2 =
        g.mean.tail<2>().cast<long double>() + c.bottomLeftCorner<2, 3>() * s11_inv * dp;
    const Eigen::Matrix<long double, 2, 2> cov2 =
        c.bottomRightCorner<2, 2>() -
        c.bottomLeftCorner<2, 3>() * s11_inv * c.topRightCorner<3, 2>();
    for (int k = 0; k < 2; ++k) {
      EXPECT_NEAR(s[3 + k], static_cast<double>(mean2[k]), 1e-9 * (1 + std::abs(s[3 + k])));
      for (int j = 0; j < 2; ++j) {
        EXPECT_NEAR(rest(3 + k, 3 + j), static_cast<double>(cov2(k, j)), 1e-12) << k << j;
      }
    }
    EXPECT_TRUE(rest.topRows<3>().isZero(0.0));
    EXPECT_TRUE(rest.leftCols<3>().isZero(0.0));
  }
}

// Drawn poses have the proposal's pose marginal, and the draw plus a draw from the left-over
// Gaussian has the whole proposal's moments (the law of total covariance), 5 sds as above.
TEST(DrawStateTest, PoseThenConditionalVelocitiesHaveTheProposalMoments) {
  std::mt19937_64 rng(47);
  std::normal_distribution<double> normal;
  PoseGaussian<5> g;
  g.mean << 1.0, -2.0, 0.5, 2.0, 0.1;
  g.cov = random_spd<5>(rng, 0.3);
  constexpr int kDraws = 200000;
  Eigen::Matrix<double, 5, 1> sum = Eigen::Matrix<double, 5, 1>::Zero();
  Eigen::Matrix<double, 5, 5> sum_sq = Eigen::Matrix<double, 5, 5>::Zero();
  for (int i = 0; i < kDraws; ++i) {
    double n[5];
    for (double& v : n) v = normal(rng);
    Eigen::Matrix<double, 5, 5> rest;
    Eigen::Matrix<double, 5, 1> s = draw_state<5>(g, n, rest);
    const Eigen::Matrix2d f = psd_factor<2>(rest.bottomRightCorner<2, 2>().eval());
    s.tail<2>() += f * Eigen::Vector2d(normal(rng), normal(rng));
    Eigen::Matrix<double, 5, 1> d = s - g.mean;
    d[2] = wrap_angle(d[2]);
    sum += d;
    sum_sq += d * d.transpose();
  }
  const Eigen::Matrix<double, 5, 1> mean = sum / kDraws;
  const Eigen::Matrix<double, 5, 5> cov = sum_sq / kDraws - mean * mean.transpose();
  for (int i = 0; i < 5; ++i) {
    EXPECT_NEAR(mean[i], 0.0, 5.0 * std::sqrt(g.cov(i, i) / kDraws));
    for (int j = 0; j < 5; ++j) {
      const double sd = std::sqrt((g.cov(i, i) * g.cov(j, j) + g.cov(i, j) * g.cov(i, j)) / kDraws);
      EXPECT_NEAR(cov(i, j), g.cov(i, j), 5.0 * sd) << "(" << i << ", " << j << ")";
    }
  }
}

}  // namespace
}  // namespace fastslam::engine
