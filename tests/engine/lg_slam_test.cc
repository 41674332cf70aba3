#include "engine/lg_slam.h"

#include <cmath>
#include <random>
#include <vector>

#include <Eigen/Core>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include "engine/landmark_ekf.h"
#include "engine/proposal.h"
#include "tests/engine/test_util.h"

namespace fastslam::engine {
namespace {

using testing::matrices_near;
using testing::numeric_jacobian;

// Dense oracles in long double (no SIMD path in Eigen, an independent computation), on the stack
// (at most 5 observations; heap-backed dynamic matrices draw false GCC 12 warnings).
constexpr int kMaxObs = 5;
using MatrixXl =
    Eigen::Matrix<long double, Eigen::Dynamic, Eigen::Dynamic, 0, 2 * kMaxObs, 2 * kMaxObs>;
using VectorXl = Eigen::Matrix<long double, Eigen::Dynamic, 1, 0, 2 * kMaxObs, 1>;

Eigen::Matrix2d random_spd2(std::mt19937_64& rng, double scale) {
  std::normal_distribution<double> n;
  Eigen::Matrix2d a;
  a << n(rng), n(rng), n(rng), n(rng);
  Eigen::Matrix2d m = scale * scale * (0.5 * a * a.transpose() + 0.1 * Eigen::Matrix2d::Identity());
  return 0.5 * (m + m.transpose());
}

TEST(LinearGaussianSlamTest, ModelsAreEquations77And78) {
  const LinearGaussianMeasurement g;
  const LinearGaussianMotion h;
  const Eigen::Vector2d mu(3.0, -1.0), s(0.5, 2.0), u(0.1, -0.2);
  EXPECT_EQ(g.predict(mu, s), mu - s);
  EXPECT_EQ(h.predict(s, u, 1.0), s + u);
  EXPECT_EQ(g.landmark_from(g.predict(mu, s), s), mu);
  const auto lin = g.linearize(mu, s);
  const std::array<bool, 2> plain = {false, false};
  EXPECT_TRUE(matrices_near(
      lin.g_landmark,
      numeric_jacobian<2, 2>([&](const Eigen::Vector2d& m) { return g.predict(m, s); }, mu, plain),
      1e-9, 0.0));
  EXPECT_TRUE(matrices_near(
      lin.g_pose,
      numeric_jacobian<2, 2>([&](const Eigen::Vector2d& x) { return g.predict(mu, x); }, s, plain),
      1e-9, 0.0));
  const double normals[2] = {1.0, -2.0};
  EXPECT_TRUE(matrices_near(h.sample(s, u, 1.0, Eigen::Vector2d(0.1, 0.3), normals),
                            (s + u + Eigen::Vector2d(0.1, -0.6)).eval(), 1e-15, 0.0));
  EXPECT_EQ(h.pose_noise(s, u, 1.0, Eigen::Matrix2d::Identity()), Eigen::Matrix2d::Identity());
}

// With linear models the FastSLAM 2.0 pieces are exact, so they must reproduce the Gaussian
// algebra of the joint distribution. Prior s ~ N(s_hat, P); landmarks m_k ~ N(mu_k, Sigma_k)
// independent; z_k = m_k - s + eps_k. Jointly Gaussian (s, z_1..z_K) with
// Cov(s, z_k) = -P, Cov(z_j, z_k) = P + [j = k] (Sigma_k + R). Folding z_1..z_K one after the
// other must give p(s | z_1..z_K) exactly, and the sum of the fold terms ln N(v; 0, L) must be
// ln p(z_1..z_K) (the chain rule), for any K.
TEST(LinearGaussianSlamTest, FoldedProposalIsTheExactJointPosterior) {
  std::mt19937_64 rng(41);
  std::normal_distribution<double> n;
  const LinearGaussianMeasurement model;
  for (int trial = 0; trial < 200; ++trial) {
    const int k_obs = 1 + trial % kMaxObs;
    PoseGaussian<2> prior;
    prior.mean << 5.0 * n(rng), 5.0 * n(rng);
    prior.cov = random_spd2(rng, 0.5);
    Eigen::Matrix2d r = random_spd2(rng, 0.1);
    std::vector<LandmarkGaussian> lms(k_obs);
    std::vector<Eigen::Vector2d> zs(k_obs);
    for (int k = 0; k < k_obs; ++k) {
      lms[k].mean << 10.0 * n(rng), 10.0 * n(rng);
      lms[k].cov = random_spd2(rng, 0.3);
      zs[k] = lms[k].mean - prior.mean + Eigen::Vector2d(n(rng), n(rng));
    }

    PoseGaussian<2> proposal = prior;
    double log_lik_sum = 0.0;
    for (int k = 0; k < k_obs; ++k) {
      double term = 0.0;
      proposal = fold_observation<2>(model, proposal, lms[k], zs[k], r, &term);
      log_lik_sum += term;
    }

    const int dim = 2 * k_obs;
    MatrixXl czz(dim, dim);
    MatrixXl csz(2, dim);
    VectorXl ez(dim);
    VectorXl zv(dim);
    for (Eigen::Index j = 0; j < k_obs; ++j) {
      csz.block(0, 2 * j, 2, 2) = -prior.cov.cast<long double>();
      ez.segment(2 * j, 2) =
          (lms[static_cast<std::size_t>(j)].mean - prior.mean).cast<long double>();
      zv.segment(2 * j, 2) = zs[static_cast<std::size_t>(j)].cast<long double>();
      for (Eigen::Index k = 0; k < k_obs; ++k) {
        Eigen::Matrix2d block = prior.cov;
        if (j == k) {
          block += lms[static_cast<std::size_t>(k)].cov + r;
        }
        czz.block(2 * j, 2 * k, 2, 2) = block.cast<long double>();
      }
    }
    const MatrixXl czz_inv = czz.inverse();
    const VectorXl innov = zv - ez;
    const VectorXl post_mean = prior.mean.cast<long double>() + csz * czz_inv * innov;
    const MatrixXl post_cov = prior.cov.cast<long double>() - csz * czz_inv * csz.transpose();
    const long double log_pz = -0.5L * dim * std::log(2.0L * static_cast<long double>(kPi)) -
                               0.5L * std::log(czz.determinant()) -
                               0.5L * innov.dot(czz_inv * innov);

    ASSERT_TRUE(matrices_near(proposal.cov, post_cov.cast<double>().eval(), 1e-13, 1e-9))
        << "trial " << trial << ", " << k_obs << " observations";
    ASSERT_TRUE(matrices_near(proposal.mean, post_mean.cast<double>().eval(), 1e-11, 1e-10))
        << "trial " << trial;
    ASSERT_NEAR(log_lik_sum, static_cast<double>(log_pz),
                1e-9 * std::max(1.0, std::abs(log_lik_sum)))
        << "trial " << trial;
  }
}

// The landmark update is exact too: after the pose is known, p(m | z, s) of the linear model.
TEST(LinearGaussianSlamTest, LandmarkUpdateIsTheExactConditional) {
  std::mt19937_64 rng(42);
  std::normal_distribution<double> n;
  const LinearGaussianMeasurement model;
  for (int trial = 0; trial < 500; ++trial) {
    LandmarkGaussian lm;
    lm.mean << 10.0 * n(rng), 10.0 * n(rng);
    lm.cov = random_spd2(rng, 1.0);
    const Eigen::Matrix2d r = random_spd2(rng, 0.2);
    const Eigen::Vector2d s(n(rng), n(rng));
    const Eigen::Vector2d z = lm.mean - s + Eigen::Vector2d(n(rng), n(rng));
    LandmarkGaussian updated = lm;
    const double log_lik = update_landmark(model, updated, s, z, r);
    // m | z ~ N(mu + Sigma (Sigma + R)^-1 (z + s - mu), Sigma - Sigma (Sigma + R)^-1 Sigma).
    const Eigen::Matrix2d gain = lm.cov * (lm.cov + r).inverse();
    const Eigen::Vector2d v = z + s - lm.mean;
    EXPECT_TRUE(matrices_near(updated.mean, (lm.mean + gain * v).eval(), 1e-12, 1e-11));
    EXPECT_TRUE(matrices_near(updated.cov, (lm.cov - gain * lm.cov).eval(), 1e-12, 1e-9));
    const Eigen::Matrix2d s_cov = lm.cov + r;
    EXPECT_NEAR(log_lik,
                -std::log(2.0 * kPi) - 0.5 * std::log(s_cov.determinant()) -
                    0.5 * v.dot(s_cov.inverse() * v),
                1e-10 * std::max(1.0, std::abs(log_lik)));
  }
}

}  // namespace
}  // namespace fastslam::engine
