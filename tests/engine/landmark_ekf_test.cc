#include "engine/landmark_ekf.h"

#include <cmath>
#include <random>
#include <stdexcept>

#include <Eigen/Core>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include "engine/measurement_model.h"
#include "tests/engine/test_util.h"

namespace fastslam::engine {
namespace {

using testing::matrices_near;
using testing::random_heading;

// A random symmetric positive definite 2x2 matrix with standard deviations in [lo, hi] and a
// correlation in (-0.9, 0.9).
Eigen::Matrix2d random_cov(std::mt19937_64& rng, double lo, double hi) {
  std::uniform_real_distribution<double> log_sd(std::log(lo), std::log(hi));
  std::uniform_real_distribution<double> corr(-0.9, 0.9);
  const double a = std::exp(log_sd(rng));
  const double b = std::exp(log_sd(rng));
  const double c = corr(rng);
  Eigen::Matrix2d m;
  m << a * a, c * a * b, c * a * b, b * b;
  return m;
}

struct Scenario {
  RangeBearingModel model;
  Pose pose;
  LandmarkGaussian lm;
  Eigen::Vector2d z;
  Eigen::Matrix2d r;
};

Scenario random_scenario(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> pos(-50.0, 50.0);
  std::uniform_real_distribution<double> range(2.0, 40.0);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  Scenario s{
      unit(rng) < 0.5 ? RangeBearingModel() : RangeBearingModel(SensorOffset{3.78, 0.5, 0.0}),
      Pose(pos(rng), pos(rng), random_heading(rng)),
      {},
      {},
      {}};
  s.lm.mean = s.model.landmark_from({range(rng), random_heading(rng)}, s.pose);
  s.lm.cov = random_cov(rng, 0.01, 2.0);
  s.r = random_cov(rng, 0.001, 0.3);
  s.r(0, 1) = s.r(1, 0) = 0.0;  // range and bearing noise independent, as in every dataset
  std::normal_distribution<double> n;
  s.z = s.model.predict(s.lm.mean, s.pose) +
        Eigen::Vector2d(0.3 * n(rng), 0.05 * n(rng));  // an innovation of ordinary size
  s.z[1] = wrap_angle(s.z[1]);
  return s;
}

// The smaller eigenvalue of a symmetric 2x2 matrix, in closed form.
double min_eigenvalue(const Eigen::Matrix2d& m) {
  const double half_trace = 0.5 * (m(0, 0) + m(1, 1));
  const double half_gap = 0.5 * (m(0, 0) - m(1, 1));
  return half_trace - std::sqrt(half_gap * half_gap + m(0, 1) * m(1, 0));
}

// ln of eq. 31 evaluated directly: |2 pi Q|^-1/2 exp(-1/2 v^T Q^-1 v), with Eigen's own
// determinant and inverse (the tests stay on fixed sizes: GCC 12 warns falsely inside Eigen's
// dynamic-size AVX-512 kernels).
double direct_log_likelihood(const Eigen::Vector2d& v, const Eigen::Matrix2d& q) {
  const Eigen::Matrix2d two_pi_q = 2.0 * kPi * q;
  const double w = std::pow(two_pi_q.determinant(), -0.5) * std::exp(-0.5 * v.dot(q.inverse() * v));
  return std::log(w);
}

TEST(LandmarkConversionTest, RoundTripsThroughTheMapStorage) {
  memory::Landmark stored{1.0, 2.0, 0.5, 0.1, 0.25, 3.0, 42, 7};
  const LandmarkGaussian g = to_gaussian(stored);
  EXPECT_EQ(g.mean, Eigen::Vector2d(1.0, 2.0));
  EXPECT_EQ(g.cov(0, 1), 0.1);
  EXPECT_EQ(g.cov(1, 0), 0.1);
  LandmarkGaussian changed = g;
  changed.mean << -4.0, 5.0;
  changed.cov << 2.0, -0.3, -0.3, 1.0;
  store_gaussian(changed, stored);
  EXPECT_EQ(stored, (memory::Landmark{-4.0, 5.0, 2.0, -0.3, 1.0, 3.0, 42, 7}));
}

// The EKF update (Joseph form) against the information form of Appendix A:
// Sigma_new^-1 = Sigma^-1 + G^T R^-1 G (eq. 83) and mu_new = mu + Sigma_new G^T R^-1 v (eq. 87),
// equivalently from the information vector Sigma^-1 mu + G^T R^-1 (v + G mu), all at the
// linearisation point (the prior mean).
TEST(LandmarkEkfTest, MatchesTheInformationFormOfAppendixA) {
  std::mt19937_64 rng(21);
  for (int i = 0; i < 2000; ++i) {
    const Scenario sc = random_scenario(rng);
    const LandmarkObservation obs = evaluate_observation(sc.model, sc.lm, sc.pose, sc.z, sc.r);
    LandmarkGaussian updated = sc.lm;
    apply_update(updated, obs, sc.r);

    const Eigen::Matrix2d g = sc.model.linearize(sc.lm.mean, sc.pose).g_landmark;
    const Eigen::Vector2d v =
        RangeBearingModel::innovation(sc.z, sc.model.predict(sc.lm.mean, sc.pose));
    const Eigen::Matrix2d r_inv = sc.r.inverse();
    const Eigen::Matrix2d info = sc.lm.cov.inverse() + g.transpose() * r_inv * g;
    const Eigen::Matrix2d cov = info.inverse();
    const Eigen::Vector2d mean = sc.lm.mean + cov * g.transpose() * r_inv * v;
    const Eigen::Vector2d eta =
        sc.lm.cov.inverse() * sc.lm.mean + g.transpose() * r_inv * (v + g * sc.lm.mean);
    const double scale = std::sqrt(cov.diagonal().maxCoeff());
    ASSERT_TRUE(matrices_near(updated.cov, cov, 1e-12 * scale * scale, 1e-8)) << "case " << i;
    ASSERT_TRUE(matrices_near(updated.mean, mean, 1e-9 * scale, 1e-12)) << "case " << i;
    ASSERT_TRUE(matrices_near(updated.mean, (cov * eta).eval(), 1e-7 * scale, 1e-10))
        << "case " << i;
    ASSERT_EQ(updated.cov(0, 1), updated.cov(1, 0));
  }
}

// The update against dense conditioning of the joint Gaussian of (landmark m, measurement z)
// under the linearisation z = z_hat + G (m - mu) + eps: joint covariance
// [[Sigma, Sigma G^T], [G Sigma, G Sigma G^T + R]]; the posterior of m given z is read off the
// joint precision (its m-block inverted), and the likelihood is the z-marginal N(z; z_hat, S).
TEST(LandmarkEkfTest, MatchesDenseJointGaussianConditioning) {
  std::mt19937_64 rng(22);
  for (int i = 0; i < 2000; ++i) {
    const Scenario sc = random_scenario(rng);
    LandmarkGaussian updated = sc.lm;
    const double log_lik = update_landmark(sc.model, updated, sc.pose, sc.z, sc.r);

    // In long double: the joint matrix is as ill-conditioned as Sigma is large against R (up to
    // about 1e8 here), which would cost the oracle itself six digits in double.
    using Matrix4l = Eigen::Matrix<long double, 4, 4>;
    using Matrix2l = Eigen::Matrix<long double, 2, 2>;
    using Vector2l = Eigen::Matrix<long double, 2, 1>;
    const auto lin = sc.model.linearize(sc.lm.mean, sc.pose);
    const Matrix2l cov_l = sc.lm.cov.cast<long double>();
    const Matrix2l g_l = lin.g_landmark.cast<long double>();
    Matrix4l joint;
    joint.topLeftCorner<2, 2>() = cov_l;
    joint.topRightCorner<2, 2>() = cov_l * g_l.transpose();
    joint.bottomLeftCorner<2, 2>() = g_l * cov_l;
    joint.bottomRightCorner<2, 2>() = g_l * cov_l * g_l.transpose() + sc.r.cast<long double>();
    const Matrix4l precision = joint.inverse();
    const Matrix2l post_cov_l = precision.topLeftCorner<2, 2>().inverse();
    // Conditional mean: mu - Lambda_mm^-1 Lambda_mz (z - z_hat), the innovation wrapped.
    const Vector2l v = RangeBearingModel::innovation(sc.z, lin.z_hat).cast<long double>();
    const Vector2l post_mean_l =
        sc.lm.mean.cast<long double>() - post_cov_l * precision.topRightCorner<2, 2>() * v;
    const Matrix2l s = joint.bottomRightCorner<2, 2>();
    const double dense_log_lik = static_cast<double>(
        -0.5L * std::log((2.0L * static_cast<long double>(kPi) * s).determinant()) -
        0.5L * v.dot(s.inverse() * v));
    const Eigen::Matrix2d post_cov = post_cov_l.cast<double>();
    const Eigen::Vector2d post_mean = post_mean_l.cast<double>();

    const double scale = std::sqrt(post_cov.diagonal().maxCoeff());
    ASSERT_TRUE(matrices_near(updated.cov, post_cov, 1e-12 * scale * scale, 1e-7)) << "case " << i;
    ASSERT_TRUE(matrices_near(updated.mean, post_mean, 1e-8 * scale, 1e-12)) << "case " << i;
    ASSERT_NEAR(log_lik, dense_log_lik, 1e-9 * std::max(1.0, std::abs(dense_log_lik)));
  }
}

// The likelihood, Mahalanobis distance and Q against eq. 31-32 built independently.
TEST(LandmarkEkfTest, LikelihoodIsEquation31) {
  std::mt19937_64 rng(23);
  for (int i = 0; i < 1000; ++i) {
    const Scenario sc = random_scenario(rng);
    const LandmarkObservation obs = evaluate_observation(sc.model, sc.lm, sc.pose, sc.z, sc.r);
    const Eigen::Matrix2d g = sc.model.linearize(sc.lm.mean, sc.pose).g_landmark;
    const Eigen::Matrix2d q = g * sc.lm.cov * g.transpose() + sc.r;
    const Eigen::Vector2d z_hat = sc.model.predict(sc.lm.mean, sc.pose);
    Eigen::Vector2d v = sc.z - z_hat;
    v[1] = wrap_angle(v[1]);
    ASSERT_TRUE(matrices_near(obs.q, q, 1e-15, 1e-12));
    ASSERT_TRUE(matrices_near(obs.innovation, v, 1e-15, 1e-12));
    ASSERT_NEAR(obs.mahalanobis2, v.dot(q.inverse() * v), 1e-9 * std::max(1.0, obs.mahalanobis2));
    const double direct = direct_log_likelihood(v, q);
    ASSERT_NEAR(obs.log_likelihood, direct, 1e-9 * std::max(1.0, std::abs(direct)));
  }
}

// Evaluating a candidate changes nothing and is repeatable (for data association).
TEST(LandmarkEkfTest, EvaluationIsPure) {
  std::mt19937_64 rng(24);
  const Scenario sc = random_scenario(rng);
  const LandmarkGaussian before = sc.lm;
  const LandmarkObservation a = evaluate_observation(sc.model, sc.lm, sc.pose, sc.z, sc.r);
  const LandmarkObservation b = evaluate_observation(sc.model, sc.lm, sc.pose, sc.z, sc.r);
  EXPECT_EQ(sc.lm.mean, before.mean);
  EXPECT_EQ(sc.lm.cov, before.cov);
  EXPECT_EQ(a.log_likelihood, b.log_likelihood);
  LandmarkGaussian via_obs = sc.lm;
  apply_update(via_obs, a, sc.r);
  LandmarkGaussian direct = sc.lm;
  update_landmark(sc.model, direct, sc.pose, sc.z, sc.r);
  EXPECT_EQ(via_obs.mean, direct.mean);
  EXPECT_EQ(via_obs.cov, direct.cov);
}

// With a measurement far more precise than the landmark (R 1e-12 of Sigma), the simple form
// (I - K G) Sigma loses positive definiteness to rounding (it did in about 13 % of such cases when
// tried); the Joseph form must not.
TEST(LandmarkEkfTest, StaysSymmetricPositiveDefiniteUnderTinyNoise) {
  std::mt19937_64 rng(25);
  for (int i = 0; i < 2000; ++i) {
    Scenario sc = random_scenario(rng);
    sc.lm.cov = random_cov(rng, 10.0, 100.0);
    sc.r << 1e-12, 0.0, 0.0, 1e-14;
    LandmarkGaussian lm = sc.lm;
    for (int k = 0; k < 20; ++k) {  // repeated updates of the same landmark
      update_landmark(sc.model, lm, sc.pose, sc.z, sc.r);
      ASSERT_EQ(lm.cov(0, 1), lm.cov(1, 0));
      ASSERT_GT(min_eigenvalue(lm.cov), 0.0) << "case " << i << " step " << k << "\n" << lm.cov;
      ASSERT_TRUE(lm.mean.allFinite());
    }
  }
}

// eq. 69-70: the new landmark reproduces z, and Sigma = J R J^T = (G^T R^-1 G)^-1 with G at it.
TEST(LandmarkEkfTest, InitialisationIsEquations69And70) {
  std::mt19937_64 rng(26);
  for (int i = 0; i < 1000; ++i) {
    const Scenario sc = random_scenario(rng);
    const LandmarkGaussian lm = initialize_landmark(sc.model, sc.pose, sc.z, sc.r);
    const Eigen::Vector2d back = sc.model.predict(lm.mean, sc.pose);
    ASSERT_NEAR(back[0], sc.z[0], 1e-10);
    ASSERT_NEAR(angle_diff(back[1], sc.z[1]), 0.0, 1e-10);
    const Eigen::Matrix2d g = sc.model.linearize(lm.mean, sc.pose).g_landmark;
    const Eigen::Matrix2d expected = (g.transpose() * sc.r.inverse() * g).inverse();
    ASSERT_TRUE(matrices_near(lm.cov, expected, 1e-14, 1e-8)) << "case " << i;
    ASSERT_EQ(lm.cov(0, 1), lm.cov(1, 0));
  }
}

// The gate's lower bound from the mean and the largest eigenvalue alone never exceeds the exact
// Mahalanobis distance (oracle: evaluate_observation), for innovations from ordinary to far
// outside any gate, with and without a sensor offset, diagonal and correlated R; it is exact
// for an isotropic covariance at zero bearing innovation, and drops most far candidates. The
// log-likelihood is at most that of Q = R at the same distance.
TEST(LandmarkEkfTest, MahalanobisBoundNeverExceedsTheExactDistance) {
  std::mt19937_64 rng(31);
  std::normal_distribution<double> n;
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  int far = 0;
  int dropped = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    Scenario s = random_scenario(rng);
    if (trial % 3 == 0) s.lm.cov = Eigen::Matrix2d::Identity() * std::exp(3.0 * n(rng));
    if (trial % 5 == 0) s.r = random_cov(rng, 0.001, 0.3);  // correlated range and bearing noise
    // Innovations from tiny to huge.
    const double scale = std::exp(2.0 * n(rng));
    s.z += Eigen::Vector2d(scale * n(rng), 0.1 * scale * n(rng));
    s.z[0] = std::max(s.z[0], 0.5);
    s.z[1] = wrap_angle(s.z[1]);
    const Eigen::Vector2d sensor = s.model.sensor_position(s.pose);
    const Eigen::Vector2d direction = (s.model.landmark_from(s.z, s.pose) - sensor) / s.z[0];
    const double half_gap = 0.5 * (s.lm.cov(0, 0) - s.lm.cov(1, 1));
    const double largest = 0.5 * (s.lm.cov(0, 0) + s.lm.cov(1, 1)) +
                           std::sqrt(half_gap * half_gap + s.lm.cov(0, 1) * s.lm.cov(0, 1));
    const double extent = trial % 2 == 0 ? largest : largest * (1.0 + 3.0 * unit(rng));
    const double bound = range_bearing_mahalanobis2_bound(sensor, direction, s.z[0], s.lm.mean[0],
                                                          s.lm.mean[1], extent, s.r);
    const LandmarkObservation obs = evaluate_observation(s.model, s.lm, s.pose, s.z, s.r);
    const double exact = obs.mahalanobis2;
    ASSERT_LE(bound, exact * (1.0 + 1e-9) + 1e-12) << "trial " << trial;
    // det Q >= det R, so ln N(v; 0, Q) <= -ln 2 pi - ln det R / 2 - m^2 / 2 (the filter's
    // limit for candidates that maximum likelihood could take).
    const double log_det_r = std::log(s.r(0, 0) * s.r(1, 1) - s.r(0, 1) * s.r(1, 0));
    ASSERT_LE(obs.log_likelihood, -kLogTwoPi - 0.5 * log_det_r - 0.5 * exact + 1e-9)
        << "trial " << trial;
    if (exact > 2.0 * 23.0) {
      ++far;
      dropped += bound > 23.0 ? 1 : 0;
    }
  }
  EXPECT_GT(far, 2000);
  EXPECT_GT(dropped, far / 2) << "the bound should drop most candidates far outside the gate";
  // Tight: an isotropic covariance, the observation straight at the landmark (no bearing
  // innovation, so the sine is exact), diagonal R.
  const RangeBearingModel model(SensorOffset{3.78, 0.5, 0.0});
  const Pose pose(10.0, -4.0, 0.7);
  LandmarkGaussian lm;
  lm.mean = model.landmark_from({25.0, 0.3}, pose);
  lm.cov = Eigen::Matrix2d::Identity() * 0.4;
  Eigen::Matrix2d r;
  r << 0.25, 0.0, 0.0, 0.0009;
  const Eigen::Vector2d z(27.5, 0.3);
  const Eigen::Vector2d sensor = model.sensor_position(pose);
  const double bound = range_bearing_mahalanobis2_bound(
      sensor, (model.landmark_from(z, pose) - sensor) / z[0], z[0], lm.mean[0], lm.mean[1], 0.4, r);
  EXPECT_NEAR(bound, evaluate_observation(model, lm, pose, z, r).mahalanobis2, 1e-9);
  EXPECT_NEAR(bound, 2.5 * 2.5 / (0.4 + 0.25), 1e-9);
}

TEST(LandmarkEkfTest, CheckCovarianceRefusesBadMatrices) {
  Eigen::Matrix2d good;
  good << 1.0, 0.5, 0.5, 1.0;
  EXPECT_NO_THROW(check_covariance2(good, "R"));
  Eigen::Matrix2d asym = good;
  asym(0, 1) = 0.4;
  EXPECT_THROW(check_covariance2(asym, "R"), std::invalid_argument);
  Eigen::Matrix2d indefinite;
  indefinite << 1.0, 2.0, 2.0, 1.0;
  EXPECT_THROW(check_covariance2(indefinite, "R"), std::invalid_argument);
  Eigen::Matrix2d nan = good;
  nan(1, 1) = std::nan("");
  EXPECT_THROW(check_covariance2(nan, "R"), std::invalid_argument);
  EXPECT_THROW(check_covariance2(Eigen::Matrix2d::Zero(), "R"), std::invalid_argument);
}

}  // namespace
}  // namespace fastslam::engine
