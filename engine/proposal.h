// The FastSLAM 2.0 pose proposal and importance weight (paper section 5, eq. 36-61, table 2).
//
// For one particle: start from the motion prediction, the Gaussian N(s_hat, P) with
// s_hat = h(u, s_{t-1}) and P = V M V^T (engine/motion_model.h). Each observation z of a known
// landmark (mu, Sigma) then refines the Gaussian proposal N(mu_s, Sigma_s):
//   z_hat = g(mu, mu_s), G_mu, G_s at (mu, mu_s)                               (eq. 36-39)
//   Q = R + G_mu Sigma G_mu^T                                                 (eq. 42)
//   Sigma_s' = (G_s^T Q^-1 G_s + Sigma_s^-1)^-1                              (eq. 48)
//   mu_s'    = Sigma_s' G_s^T Q^-1 (z - z_hat) + mu_s                        (eq. 49)
// and the refined Gaussian is the prior of the next observation of the scan; the pose is drawn
// once at the end (`draw_state`: `sample_pose` for the pose, the no-odometry velocities kept as
// their Gaussian given it), and every landmark is then updated at the DRAWN pose with the
// FastSLAM 1.0 update (eq. 53-55, engine/landmark_ekf.h).
//
// Where it linearises, why the Kalman form and how the terms of several observations combine
// into one weight: docs/engine.md ("The FastSLAM 2.0 proposal").
//
// State dimension N: the pose is (x, y, theta) (N = 3); (x, y, theta, v, omega or kappa) for
// the no-odometry models (N = 5, the extra columns of G_s are zero; the velocities are not drawn
// but carried as a Gaussian from scan to scan, `draw_state`); (x, y) for LG-SLAM (N = 2,
// engine/lg_slam.h). Component 2 is the heading, wrapped to (-pi, pi], when N >= 3.
//
// Ownership: values in, values out. Thread safety: pure functions. Cost: O(N^2) flops on fixed-size
// matrices, one 2x2 inversion and one log per observation; no allocation, all inline.
#pragma once

#include <cmath>

#include <Eigen/Core>

#include "engine/angles.h"
#include "engine/landmark_ekf.h"
#include "engine/measurement_model.h"

namespace fastslam::engine {

// The index of the heading in a state of N components, or -1 (LG-SLAM positions).
template <int N>
inline constexpr int kHeadingIndex = N >= 3 ? 2 : -1;

// A Gaussian over the state: the proposal N(mu_s, Sigma_s), or the motion prior N(s_hat, P).
template <int N>
struct PoseGaussian {
  Eigen::Matrix<double, N, 1> mean = Eigen::Matrix<double, N, 1>::Zero();
  Eigen::Matrix<double, N, N> cov = Eigen::Matrix<double, N, N>::Zero();
};
using PoseProposal = PoseGaussian<3>;

// One observation of one landmark against the current proposal; nothing is modified.
template <int N>
struct ProposalObservation {
  Eigen::Vector2d z_hat;               // g(mu, mu_s)
  Eigen::Vector2d innovation;          // v = z - z_hat, bearing wrapped
  Eigen::Matrix2d g_landmark;          // G_mu at (mu, mu_s)
  Eigen::Matrix<double, 2, N> g_pose;  // G_s at (mu, mu_s)
  Eigen::Matrix2d q;                   // Q = R + G_mu Sigma G_mu^T (eq. 42)
  Eigen::Matrix2d l;                   // L = G_s Sigma_s G_s^T + Q (eq. 60 at Sigma_s)
  Eigen::Matrix2d l_inv;               // L^-1
  double log_det_l = 0.0;              // ln det L
  double mahalanobis2 = 0.0;           // v^T L^-1 v
  // ln N(v; 0, L) (eq. 61 at the current proposal); after scale_weight, ln N(v; 0, L + (k - 1)
  // R), the likelihood the association and the weight use.
  double log_likelihood = 0.0;
};

// The factor on R in FastSLAM 2.0's association and weight likelihoods for measurement errors
// of lag-1 correlation rho from scan to scan (FilterConfig::error_correlation): n sightings then
// carry the information of n (1 - rho) / (1 + rho) independent ones. 1 for rho = 0.
inline double weight_scale(double error_correlation) {
  return (1.0 + error_correlation) / (1.0 - error_correlation);
}

// Core: the terms from a linearisation at (mu, mu_s) and the wrapped innovation.
// REQUIRES: landmark_cov and proposal.cov symmetric PSD, r symmetric positive definite.
template <int N>
inline ProposalObservation<N> evaluate_proposal(const MeasurementLinearization<N>& lin,
                                                const Eigen::Vector2d& innovation,
                                                const Eigen::Matrix2d& landmark_cov,
                                                const PoseGaussian<N>& proposal,
                                                const Eigen::Matrix2d& r) {
  ProposalObservation<N> out;
  out.z_hat = lin.z_hat;
  out.innovation = innovation;
  out.g_landmark = lin.g_landmark;
  out.g_pose = lin.g_pose;
  Eigen::Matrix2d q = lin.g_landmark * landmark_cov * lin.g_landmark.transpose() + r;
  q(0, 1) = q(1, 0) = 0.5 * (q(0, 1) + q(1, 0));
  out.q = q;
  const Eigen::Matrix<double, 2, N> gp = lin.g_pose * proposal.cov;
  Eigen::Matrix2d l = gp * lin.g_pose.transpose() + q;
  l(0, 1) = l(1, 0) = 0.5 * (l(0, 1) + l(1, 0));
  out.l = l;
  const SymmetricInverse2 inv = invert_symmetric2(l);
  out.l_inv = inv.inverse;
  out.log_det_l = inv.log_det;
  out.mahalanobis2 = innovation.dot(inv.inverse * innovation);
  out.log_likelihood = gaussian_log_density2(out.mahalanobis2, inv.log_det);
  return out;
}

// The likelihood of `obs` rescored under L + (weight_scale - 1) R (weight_scale above): what
// the association and the weight use; the terms the fold reads stay. A separate step, so that
// evaluate_proposal compiles as it does without it.
template <int N>
inline void scale_weight(ProposalObservation<N>& obs, const Eigen::Matrix2d& r,
                         double weight_scale) {
  Eigen::Matrix2d lw = obs.l + (weight_scale - 1.0) * r;
  lw(0, 1) = lw(1, 0) = 0.5 * (lw(0, 1) + lw(1, 0));
  const SymmetricInverse2 w = invert_symmetric2(lw);
  obs.log_likelihood =
      gaussian_log_density2(obs.innovation.dot(w.inverse * obs.innovation), w.log_det);
}

// `model.linearize` for the model's own pose, `linearize_state<N>` for a longer state.
template <int N, MeasurementModel Model>
inline MeasurementLinearization<N> linearize_for(const Model& model,
                                                 const Eigen::Vector2d& landmark,
                                                 const Eigen::Matrix<double, N, 1>& state) {
  if constexpr (N == Model::kPoseDim) {
    return model.linearize(landmark, state);
  } else {
    return model.template linearize_state<N>(landmark, state);
  }
}

// The terms of observation z of landmark `lm` against `proposal`, linearised at its mean.
template <int N, MeasurementModel Model>
inline ProposalObservation<N> evaluate_proposal(const Model& model, const LandmarkGaussian& lm,
                                                const PoseGaussian<N>& proposal,
                                                const Eigen::Vector2d& z,
                                                const Eigen::Matrix2d& r) {
  const MeasurementLinearization<N> lin = linearize_for<N>(model, lm.mean, proposal.mean);
  return evaluate_proposal<N>(lin, Model::innovation(z, lin.z_hat), lm.cov, proposal, r);
}

// The proposal refined by one observation (eq. 48-49, Kalman form; see the file comment).
// `obs` must have been evaluated against this very proposal.
template <int N>
inline PoseGaussian<N> fold(const PoseGaussian<N>& proposal, const ProposalObservation<N>& obs) {
  using Gain = Eigen::Matrix<double, N, 2>;
  using Square = Eigen::Matrix<double, N, N>;
  const Gain k = proposal.cov * obs.g_pose.transpose() * obs.l_inv;  // K = Sigma_s G_s^T L^-1
  PoseGaussian<N> out;
  out.mean = proposal.mean + k * obs.innovation;
  if constexpr (kHeadingIndex<N> >= 0) {
    out.mean[kHeadingIndex<N>] = wrap_angle(out.mean[kHeadingIndex<N>]);
  }
  const Square a = Square::Identity() - k * obs.g_pose;
  const Square cov = a * proposal.cov * a.transpose() + k * obs.q * k.transpose();
  out.cov = 0.5 * (cov + cov.transpose());
  return out;
}

// Evaluate and fold in one call; returns the observation's log-likelihood term through
// `log_likelihood` (may be null).
template <int N, MeasurementModel Model>
inline PoseGaussian<N> fold_observation(const Model& model, const PoseGaussian<N>& proposal,
                                        const LandmarkGaussian& lm, const Eigen::Vector2d& z,
                                        const Eigen::Matrix2d& r,
                                        double* log_likelihood = nullptr) {
  const ProposalObservation<N> obs = evaluate_proposal<N>(model, lm, proposal, z, r);
  if (log_likelihood != nullptr) {
    *log_likelihood = obs.log_likelihood;
  }
  return fold<N>(proposal, obs);
}

// The importance weight term of eq. 60-61 for one observation, in log space:
// ln N(z - g(mu, s_hat); 0, L), L = G_s P G_s^T + G_mu Sigma G_mu^T + R, all at s_hat.
template <int N, MeasurementModel Model>
inline double log_weight(const Model& model, const LandmarkGaussian& lm,
                         const PoseGaussian<N>& motion_prior, const Eigen::Vector2d& z,
                         const Eigen::Matrix2d& r) {
  return evaluate_proposal<N>(model, lm, motion_prior, z, r).log_likelihood;
}

// A lower-triangular factor F with F F^T = cov for a symmetric positive SEMIdefinite cov: a
// Cholesky factorisation whose pivots at or below a relative threshold (rounding noise of a
// singular matrix, such as a rank-2 P) give zero columns. O(N^3 / 6), no allocation.
template <int N>
inline Eigen::Matrix<double, N, N> psd_factor(const Eigen::Matrix<double, N, N>& cov) {
  Eigen::Matrix<double, N, N> f = Eigen::Matrix<double, N, N>::Zero();
  const double scale = cov.diagonal().cwiseAbs().maxCoeff();
  const double threshold = 64.0 * N * 2.220446049250313e-16 * scale;
  for (int j = 0; j < N; ++j) {
    double d = cov(j, j);
    for (int k = 0; k < j; ++k) {
      d -= f(j, k) * f(j, k);
    }
    if (!(d > threshold)) {
      continue;  // column j stays zero
    }
    const double root = std::sqrt(d);
    f(j, j) = root;
    for (int i = j + 1; i < N; ++i) {
      double e = cov(i, j);
      for (int k = 0; k < j; ++k) {
        e -= f(i, k) * f(j, k);
      }
      f(i, j) = e / root;
    }
  }
  return f;
}

// A draw from N(mean, cov) given N standard normals at `normals` (the caller's random stream):
// mean + F n with F = psd_factor(cov), heading wrapped. With normals = 0 it is the mean.
// REQUIRES: normals points at N readable doubles.
template <int N>
inline Eigen::Matrix<double, N, 1> sample_pose(const PoseGaussian<N>& proposal,
                                               const double* normals) {
  Eigen::Matrix<double, N, 1> s =
      proposal.mean +
      psd_factor<N>(proposal.cov) * Eigen::Map<const Eigen::Matrix<double, N, 1>>(normals);
  if constexpr (kHeadingIndex<N> >= 0) {
    s[kHeadingIndex<N>] = wrap_angle(s[kHeadingIndex<N>]);
  }
  return s;
}

// The pose's dimension within a state of N components (the first min(N, 3)).
template <int kN>
inline constexpr int kPoseDimOf = kN < 3 ? kN : 3;

// What draw_state leaves: the covariance of the components after the pose given the pose, from
// F = psd_factor(cov) (F22 F22^T in the lower-right block, zero elsewhere; zero for N <= 3).
template <int N>
inline Eigen::Matrix<double, N, N> rest_given_pose(const Eigen::Matrix<double, N, N>& f) {
  constexpr int kRest = N - kPoseDimOf<N>;
  Eigen::Matrix<double, N, N> out = Eigen::Matrix<double, N, N>::Zero();
  if constexpr (kRest > 0) {
    const Eigen::Matrix<double, kRest, kRest> f22 = f.template bottomRightCorner<kRest, kRest>();
    out.template bottomRightCorner<kRest, kRest>() = f22 * f22.transpose();
  }
  return out;
}

// The FastSLAM 2.0 draw: the pose (components 0-2) from the proposal; for a longer state (N = 5,
// the no-odometry velocities v, omega) the rest is NOT drawn but kept as the Gaussian
// conditioned on the drawn pose: its mean goes into the returned state and its covariance into
// the lower-right block of `cov_after` (zero elsewhere), where the next prediction starts from.
// Given the pose path the velocities enter the motion linearly (eq. 81), so this is the
// Rao-Blackwellised treatment of them (a marginalised particle filter); with the curvature walk
// (theta_dot = v kappa, bilinear) it is the same treatment of the linearised motion. Drawing them
// as well would make the next prior treat them as exact: a wrong v or omega could then never be
// corrected by a measurement, only by resampling, and FastSLAM 2.0 with one particle diverged
// on Victoria Park without odometry (docs/victoria-park.md). With F = psd_factor(cov) lower
// triangular the draw is mean + F n with n's components from 3 on set to zero, and the
// conditional covariance is F22 F22^T (F22 = F's lower-right block). For N <= 3 this is
// exactly sample_pose and a zero covariance. REQUIRES: normals points at N readable doubles.
template <int N>
inline Eigen::Matrix<double, N, 1> draw_state(const PoseGaussian<N>& proposal,
                                              const double* normals,
                                              Eigen::Matrix<double, N, N>& cov_after) {
  const Eigen::Matrix<double, N, N> f = psd_factor<N>(proposal.cov);
  Eigen::Matrix<double, N, 1> n = Eigen::Map<const Eigen::Matrix<double, N, 1>>(normals);
  if constexpr (N > kPoseDimOf<N>) n.template tail<N - kPoseDimOf<N>>().setZero();
  cov_after = rest_given_pose<N>(f);
  Eigen::Matrix<double, N, 1> s = proposal.mean + f * n;
  if constexpr (kHeadingIndex<N> >= 0) {
    s[kHeadingIndex<N>] = wrap_angle(s[kHeadingIndex<N>]);
  }
  return s;
}

}  // namespace fastslam::engine
