// The per-landmark EKF of FastSLAM 1.0 (paper eq. 25, 31, 32; section 4, table 1), the function
// the filter calls per particle per observation under unknown association (known association
// runs its lane form, engine/landmark_batch.h), and the landmark initialisation (eq. 69-70).
//
// Two steps, so that unknown data association can score candidates before choosing one:
//   evaluate_observation(model, lm, s, z, R)  -> LandmarkObservation: z_hat, v = z - z_hat
//       (bearing wrapped), G = G_mu, Q = G Sigma G^T + R (eq. 32), Q^-1, the squared Mahalanobis
//       distance v^T Q^-1 v (for gating) and ln N(v; 0, Q) (eq. 31, in log space). Changes nothing.
//   apply_update(lm, obs, R)  -> K = Sigma G^T Q^-1, mu += K v, and the covariance in Joseph form
//       Sigma = (I - K G) Sigma (I - K G)^T + K R K^T (eq. 25), which stays symmetric positive
//       definite even when R is small against G Sigma G^T, where (I - K G) Sigma may not.
// `update_landmark` does both and returns the log-likelihood; `range_bearing_mahalanobis2_bound`
// bounds evaluate_observation's Mahalanobis distance from below without the covariance (a gate's
// cheap first test). Everything is linearised at the
// landmark's prior mean and the given pose (in FastSLAM 2.0: the pose drawn from the proposal,
// eq. 51-55). The core overloads take (G, v) directly, so any measurement model plugs in.
//
// Ownership: plain values in, values out; `apply_update` writes only the landmark it is given.
// Thread safety: pure functions. Cost: O(1), a few dozen flops on fixed-size 2x2 matrices plus
// the model's linearisation (one sqrt, one atan2 for range-bearing); no allocation, all inline.
#pragma once

#include <algorithm>
#include <cmath>

#include <Eigen/Core>

#include "engine/measurement_model.h"
#include "memory/landmark_tree.h"

namespace fastslam::engine {

// ln(2 pi): the normaliser of a 2-D Gaussian is -ln(2 pi) - ln(det) / 2.
inline constexpr double kLogTwoPi = 1.8378770664093454836;

// A landmark's position estimate: mean mu and covariance Sigma (symmetric positive definite).
struct LandmarkGaussian {
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
};

// Conversions to and from the map's storage (memory/landmark_tree.h). `store_gaussian` writes the
// mean and covariance only (sxy from the upper triangle) and leaves log_odds, id and last_seen.
inline LandmarkGaussian to_gaussian(const memory::Landmark& lm) {
  LandmarkGaussian g;
  g.mean << lm.x, lm.y;
  g.cov << lm.sxx, lm.sxy, lm.sxy, lm.syy;
  return g;
}
inline void store_gaussian(const LandmarkGaussian& g, memory::Landmark& lm) {
  lm.x = g.mean[0];
  lm.y = g.mean[1];
  lm.sxx = g.cov(0, 0);
  lm.sxy = g.cov(0, 1);
  lm.syy = g.cov(1, 1);
}

// The inverse and log-determinant of a symmetric positive definite 2x2 matrix (closed form).
struct SymmetricInverse2 {
  Eigen::Matrix2d inverse;
  double log_det = 0.0;
};
inline SymmetricInverse2 invert_symmetric2(const Eigen::Matrix2d& a) {
  const double b = 0.5 * (a(0, 1) + a(1, 0));
  const double det = a(0, 0) * a(1, 1) - b * b;
  const double inv_det = 1.0 / det;
  SymmetricInverse2 out;
  out.inverse << a(1, 1) * inv_det, -b * inv_det,  //
      -b * inv_det, a(0, 0) * inv_det;
  out.log_det = std::log(det);
  return out;
}

// Throws std::invalid_argument naming `what` unless `m` is finite, symmetric (to a relative 1e-9)
// and positive definite: for configuration checks (R, initial covariances), not the hot path.
void check_covariance2(const Eigen::Matrix2d& m, const char* what);

// ln N(v; 0, S) given S^-1's quadratic form m2 = v^T S^-1 v and ln det S.
inline double gaussian_log_density2(double mahalanobis2, double log_det) {
  return -kLogTwoPi - 0.5 * log_det - 0.5 * mahalanobis2;
}

// Everything one observation says about one candidate landmark (eq. 31-32), before any update.
struct LandmarkObservation {
  Eigen::Vector2d z_hat;        // g(mu, s)
  Eigen::Vector2d innovation;   // v = z - z_hat, bearing wrapped
  Eigen::Matrix2d g;            // G_mu at (mu, s)
  Eigen::Matrix2d q;            // Q = G Sigma G^T + R (eq. 32), symmetric
  Eigen::Matrix2d q_inv;        // Q^-1
  double log_det_q = 0.0;       // ln det Q
  double mahalanobis2 = 0.0;    // v^T Q^-1 v (chi-square, 2 dof, under the model)
  double log_likelihood = 0.0;  // ln N(v; 0, Q) = ln w of eq. 31
};

// Core: the observation terms from G_mu and the innovation, for a landmark of covariance `cov`.
// REQUIRES: cov symmetric positive semidefinite and R symmetric positive definite.
inline LandmarkObservation evaluate_observation(const Eigen::Matrix2d& g,
                                                const Eigen::Vector2d& innovation,
                                                const Eigen::Matrix2d& cov,
                                                const Eigen::Matrix2d& r) {
  LandmarkObservation obs;
  obs.g = g;
  obs.innovation = innovation;
  const Eigen::Matrix2d gs = g * cov;
  Eigen::Matrix2d q = gs * g.transpose() + r;
  q(0, 1) = q(1, 0) = 0.5 * (q(0, 1) + q(1, 0));
  obs.q = q;
  // Q^-1 = adj(Q) / det Q; the quadratic form uses adj(Q) directly, so the division, the log and
  // the products run side by side instead of one after the other.
  const double det = q(0, 0) * q(1, 1) - q(0, 1) * q(0, 1);
  const double inv_det = 1.0 / det;
  const double quad = innovation[0] * innovation[0] * q(1, 1) -
                      2.0 * innovation[0] * innovation[1] * q(0, 1) +
                      innovation[1] * innovation[1] * q(0, 0);
  obs.q_inv << q(1, 1) * inv_det, -q(0, 1) * inv_det,  //
      -q(0, 1) * inv_det, q(0, 0) * inv_det;
  obs.log_det_q = std::log(det);
  obs.mahalanobis2 = quad * inv_det;
  obs.log_likelihood = gaussian_log_density2(obs.mahalanobis2, obs.log_det_q);
  return obs;
}

// A lower bound on evaluate_observation(RangeBearingModel, lm, s, z, R).mahalanobis2 from the
// landmark's mean (x, y) and a bound `extent` on its covariance's largest eigenvalue alone: no
// covariance, no trigonometry, so a gate can drop most candidates before reading the map.
// `sensor` is the sensor's position at s and `direction` the unit vector of z's bearing in the
// world (sensor + z[0] * direction = the landmark position z implies).
// Why it holds: G = G_mu has rows (d / r) and (perp(d) / q) for the offset d = mu - sensor,
// q = |d|^2, so G G^T = diag(1, 1/q); Sigma <= extent I gives Q = G Sigma G^T + R <= Qb =
// extent diag(1, 1/q) + R, hence v^T Q^-1 v >= v^T Qb^-1 v. With R diagonal, Qb is diagonal:
// v_r^2 / (extent + R_rr) + v_b^2 q / (extent + q R_bb), where v_r = z[0] - r exactly and
// |v_b| >= |sin v_b| = |direction x d| / r. With R not diagonal, the larger of the two terms
// (each v_i^2 / Qb_ii <= v^T Qb^-1 v) is the bound. Rounding: a few ulps of either side, so a
// caller that drops a candidate when the bound exceeds the gate by a relative 1e-6 drops only
// what the exact gate would drop. REQUIRES: extent >= the largest eigenvalue, R SPD.
inline double range_bearing_mahalanobis2_bound(const Eigen::Vector2d& sensor,
                                               const Eigen::Vector2d& direction, double range,
                                               double x, double y, double extent,
                                               const Eigen::Matrix2d& r) {
  const double dx = x - sensor[0];
  const double dy = y - sensor[1];
  const double q = dx * dx + dy * dy;
  const double v_r = range - std::sqrt(q);
  const double cross = direction[0] * dy - direction[1] * dx;
  const double range_term = v_r * v_r / (extent + r(0, 0));
  const double bearing_term = cross * cross / (extent + q * r(1, 1));
  return r(0, 1) == 0.0 && r(1, 0) == 0.0 ? range_term + bearing_term
                                          : std::max(range_term, bearing_term);
}

// The observation terms of z for landmark `lm` seen from pose `s` under `model`.
template <MeasurementModel Model>
inline LandmarkObservation evaluate_observation(const Model& model, const LandmarkGaussian& lm,
                                                const typename Model::PoseType& s,
                                                const Eigen::Vector2d& z,
                                                const Eigen::Matrix2d& r) {
  const auto lin = model.linearize(lm.mean, s);
  LandmarkObservation obs =
      evaluate_observation(lin.g_landmark, Model::innovation(z, lin.z_hat), lm.cov, r);
  obs.z_hat = lin.z_hat;
  return obs;
}

// The EKF update of eq. 25 with the terms `obs` computed for this landmark (same mean and
// covariance as when evaluated) and the same R. Joseph form; the result is exactly symmetric.
inline void apply_update(LandmarkGaussian& lm, const LandmarkObservation& obs,
                         const Eigen::Matrix2d& r) {
  const Eigen::Matrix2d k = lm.cov * obs.g.transpose() * obs.q_inv;  // K = Sigma G^T Q^-1
  lm.mean += k * obs.innovation;
  const Eigen::Matrix2d a = Eigen::Matrix2d::Identity() - k * obs.g;
  Eigen::Matrix2d cov = a * lm.cov * a.transpose() + k * r * k.transpose();
  cov(0, 1) = cov(1, 0) = 0.5 * (cov(0, 1) + cov(1, 0));
  lm.cov = cov;
}

// Evaluate and update in one call (FastSLAM 1.0, known association). Returns ln w (eq. 31).
template <MeasurementModel Model>
inline double update_landmark(const Model& model, LandmarkGaussian& lm,
                              const typename Model::PoseType& s, const Eigen::Vector2d& z,
                              const Eigen::Matrix2d& r) {
  const LandmarkObservation obs = evaluate_observation(model, lm, s, z, r);
  apply_update(lm, obs, r);
  return obs.log_likelihood;
}

// A new landmark from one observation (eq. 69-70): mu = g^-1(z, s), Sigma = J R J^T with
// J = d g^-1 / dz = G_mu^-1, i.e. (G_mu^T R^-1 G_mu)^-1. Its weight factor p0 (eq. 71) is the
// caller's. REQUIRES: z has a positive range (the inverse is singular at range 0).
template <MeasurementModel Model>
inline LandmarkGaussian initialize_landmark(const Model& model, const typename Model::PoseType& s,
                                            const Eigen::Vector2d& z, const Eigen::Matrix2d& r) {
  LandmarkGaussian lm;
  lm.mean = model.landmark_from(z, s);
  const Eigen::Matrix2d j = model.inverse_jacobian_measurement(z, s);
  Eigen::Matrix2d cov = j * r * j.transpose();
  cov(0, 1) = cov(1, 0) = 0.5 * (cov(0, 1) + cov(1, 0));
  lm.cov = cov;
  return lm;
}

}  // namespace fastslam::engine
