// The composed motion (FilterConfig::motion_draw = MotionDraw::kComposed): the controls queued
// since the last scan are split into runs, and each run moves a particle once instead of once
// per control. An odometry model is equivariant under rigid motions (h(u, T s) = T h(u, s)), so
// the motion of a run in the frame of the pose it starts from is the same for every particle:
// its mean displacement d (x, y, theta), to first order in the control noise its covariance C
// (Sigma <- J Sigma J^T + V M V^T control by control, at the run's mean path) and the Jacobian
// of its end by its start are computed once per pass (compose_runs). FastSLAM 1.0 then draws
// each particle's motion from that Gaussian, s <- s (+) (d + F n), F F^T = C, n three standard
// normals (apply_run): three normals and one sine and cosine per particle and run, where the
// draw per control takes two normals and a sine and cosine per control. FastSLAM 2.0 carries
// its prior's mean and covariance through the run (apply_run_mean, predict_run_covariance):
// the same, up to rounding, as its prediction control by control.
//
// A run ends after kRunMaxControls controls or once its heading variance reaches
// kRunHeadingVariance, where the first-order Gaussian stops being close to the draw per
// control (the banana of a long unobserved drive). docs/engine-config.md ("The motion draw")
// has the accuracy and speed measured against the draw per control.
//
// Only the odometry models (bailey-car, unicycle, ackermann; state (x, y, theta)) compose:
// the no-odometry walks carry per-particle velocities. Pure functions; the runs are value
// types, read concurrently by the blocks of a pass. Costs: compose_runs O(K) 3x3 products for
// K controls (one eigen-decomposition per run); the lane kernels O(lanes), vectorised.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numbers>
#include <span>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Eigenvalues>

#include "engine/angles.h"
#include "engine/motion_batch.h"
#include "parallel/vector_math.h"

namespace fastslam::engine {

// A run holds at most this many controls (the motion stage's batch).
inline constexpr std::size_t kRunMaxControls = 64;
// A run ends once the variance of its heading reaches this (0.05 rad squared): the position's
// first-order error grows with the square of the heading's spread.
inline constexpr double kRunHeadingVariance = 0.05 * 0.05;

// One run: controls [first, first + count) of the pass, its mean displacement in the frame of
// its start pose, a factor F of the displacement's covariance C (F F^T = C), C itself, and the
// Jacobian of the run's end pose by its start pose in that frame, which for the odometry models
// is the identity but for column 2: (0, 2) = a, (1, 2) = b (a heading error at the start swings
// the end point).
struct MotionRun {
  std::size_t first = 0;
  std::size_t count = 0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Matrix3d factor = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  double swing_x = 0.0;  // a
  double swing_y = 0.0;  // b
};

// The runs of `steps` for `model` with control noise `sigmas` (replacing `runs`), and in
// `partial` the mean displacement after each control from the start of its run (partial[k] for
// control k; the trajectory's points between scans).
template <class Model>
void compose_runs(const Model& model, std::span<const ControlStep> steps,
                  const typename Model::Control& sigmas, std::vector<MotionRun>& runs,
                  std::vector<Eigen::Vector3d>& partial) {
  static_assert(Model::kStateDim == 3 && !Model::kNoOdometry,
                "only the odometry models compose (engine/motion_run.h)");
  using State = typename Model::State;
  const typename Model::ControlCovariance m = Model::control_covariance(sigmas);
  runs.clear();
  partial.resize(steps.size());
  State rel = State::Zero();
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d jac = Eigen::Matrix3d::Identity();
  MotionRun run;
  auto close = [&]() {
    run.mean = rel;
    run.cov = 0.5 * (cov + cov.transpose());
    run.swing_x = jac(0, 2);
    run.swing_y = jac(1, 2);
    // F = U sqrt(D): any factor of a symmetric positive semidefinite C (C may be singular: a
    // single control of two components spans a plane of the three).
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(0.5 * (cov + cov.transpose()));
    run.factor = eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).cwiseSqrt().asDiagonal();
    runs.push_back(run);
    rel.setZero();
    cov.setZero();
    jac.setIdentity();
  };
  for (std::size_t k = 0; k < steps.size(); ++k) {
    if (run.count == 0) run.first = k;
    const typename Model::Control u(steps[k].u0, steps[k].u1);
    const double dt = steps[k].dt;
    const Eigen::Matrix3d j = model.jacobian_pose(rel, u, dt);
    cov = j * cov * j.transpose() + model.pose_noise(rel, u, dt, m);
    jac = j * jac;
    rel = model.predict(rel, u, dt);
    partial[k] = rel;
    ++run.count;
    if (run.count == kRunMaxControls || cov(2, 2) >= kRunHeadingVariance || k + 1 == steps.size()) {
      close();
      run = MotionRun{};
    }
  }
}

// a wrapped to (-pi, pi] for a in (-2 pi, 2 pi]: a select between constants and an unconditional
// subtraction, so that the lane loops if-convert and vectorise.
[[gnu::always_inline]] inline double wrap_once(double a) noexcept {
  return a - ((a > kPi ? 2 * kPi : 0.0) - (a <= -kPi ? 2 * kPi : 0.0));
}

// One lane's s <- s (+) (dx, dy, dt), the heading wrapped (|theta| <= pi, |dt| < pi).
[[gnu::always_inline]] inline void move_lane(double dx, double dy, double dt, double& x, double& y,
                                             double& theta) noexcept {
  using parallel::madd;
  double c = 0.0;
  double s = 0.0;
  parallel::sincos(theta, c, s);
  x = madd(c, dx, madd(-s, dy, x));
  y = madd(s, dx, madd(c, dy, y));
  theta = wrap_once(theta + dt);
}

// Moves lanes [0, lanes) of (x, y, theta) by one run: s <- s (+) (run.mean + run.factor n) with
// n = (n0[l], n1[l], n2[l]); the heading wrapped to (-pi, pi]. REQUIRES: |theta| <= pi and
// |run.mean[2] + the drawn heading noise| < pi (a run's heading spread is bounded above).
inline void apply_run(const MotionRun& run, std::size_t lanes, double* __restrict x,
                      double* __restrict y, double* __restrict theta, const double* __restrict n0,
                      const double* __restrict n1, const double* __restrict n2) noexcept {
  using parallel::madd;
  const Eigen::Matrix3d& f = run.factor;
  const double mx = run.mean[0], my = run.mean[1], mt = run.mean[2];
  const double f00 = f(0, 0), f01 = f(0, 1), f02 = f(0, 2);
  const double f10 = f(1, 0), f11 = f(1, 1), f12 = f(1, 2);
  const double f20 = f(2, 0), f21 = f(2, 1), f22 = f(2, 2);
  for (std::size_t l = 0; l < lanes; ++l) {
    const double dx = madd(f02, n2[l], madd(f01, n1[l], madd(f00, n0[l], mx)));
    const double dy = madd(f12, n2[l], madd(f11, n1[l], madd(f10, n0[l], my)));
    const double dt = madd(f22, n2[l], madd(f21, n1[l], madd(f20, n0[l], mt)));
    move_lane(dx, dy, dt, x[l], y[l], theta[l]);
  }
}

namespace motion_run_internal {

// predict_run_covariance's loop: the columns as restrict parameters, so that it vectorises
// without alias checks (GCC honours restrict on parameters, not on locals).
inline void predict_lanes(const MotionRun& run, std::size_t lanes, const double* __restrict theta,
                          double* __restrict p0, double* __restrict p1, double* __restrict p2,
                          double* __restrict p3, double* __restrict p4,
                          double* __restrict p5) noexcept {
  using parallel::madd;
  const double a = run.swing_x, b = run.swing_y;
  const double c00 = run.cov(0, 0), c01 = run.cov(0, 1), c02 = run.cov(0, 2);
  const double c11 = run.cov(1, 1), c12 = run.cov(1, 2), c22 = run.cov(2, 2);
  for (std::size_t l = 0; l < lanes; ++l) {
    double c = 0.0;
    double s = 0.0;
    parallel::sincos(theta[l], c, s);
    const double cc = c * c, ss = s * s, cs = c * s;
    const double p00 = p0[l], p01 = p1[l], p02 = p2[l];
    const double p11 = p3[l], p12 = p4[l], p22 = p5[l];
    // R = T^T P T: the covariance in the run's start frame.
    const double two_cs_p01 = 2 * cs * p01;
    const double r00 = madd(ss, p11, madd(cc, p00, two_cs_p01));
    const double r11 = madd(cc, p11, madd(ss, p00, -two_cs_p01));
    const double r01 = madd(cs, p11 - p00, (cc - ss) * p01);
    const double r02 = madd(s, p12, c * p02);
    const double r12 = madd(c, p12, -s * p02);
    const double r22 = p22;
    // Q = J R J^T + C.
    const double q02 = madd(a, r22, r02) + c02;
    const double q12 = madd(b, r22, r12) + c12;
    const double q00 = madd(a * a, r22, madd(2 * a, r02, r00)) + c00;
    const double q11 = madd(b * b, r22, madd(2 * b, r12, r11)) + c11;
    const double q01 = madd(a * b, r22, madd(b, r02, madd(a, r12, r01))) + c01;
    const double q22 = r22 + c22;
    // T Q T^T: back in the world.
    const double two_cs_q01 = 2 * cs * q01;
    p0[l] = madd(ss, q11, madd(cc, q00, -two_cs_q01));
    p3[l] = madd(cc, q11, madd(ss, q00, two_cs_q01));
    p1[l] = madd(cs, q00 - q11, (cc - ss) * q01);
    p2[l] = madd(-s, q12, c * q02);
    p4[l] = madd(c, q12, s * q02);
    p5[l] = q22;
  }
}

}  // namespace motion_run_internal

// FastSLAM 2.0's prior over one run: lanes [0, lanes) with headings `theta` at the run's start
// and covariances P (upper triangles, columns p[0..5] = (0,0), (0,1), (0,2), (1,1), (1,2), (2,2))
// become T (J T^T P T J^T + C) T^T, T the rotation by theta and J the run's Jacobian: what the
// prediction control by control gives, the models being equivariant (the linearisation at a
// particle's own mean path is the run's, turned by its heading). Call before apply_run_mean.
inline void predict_run_covariance(const MotionRun& run, std::size_t lanes, const double* theta,
                                   double* const p[6]) noexcept {
  motion_run_internal::predict_lanes(run, lanes, theta, p[0], p[1], p[2], p[3], p[4], p[5]);
}

// FastSLAM 2.0's mean over one run: s <- s (+) run.mean, lanes [0, lanes).
inline void apply_run_mean(const MotionRun& run, std::size_t lanes, double* __restrict x,
                           double* __restrict y, double* __restrict theta) noexcept {
  const double mx = run.mean[0], my = run.mean[1], mt = run.mean[2];
  for (std::size_t l = 0; l < lanes; ++l) move_lane(mx, my, mt, x[l], y[l], theta[l]);
}

}  // namespace fastslam::engine
