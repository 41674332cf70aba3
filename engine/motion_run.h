// The composed motion draw (FilterConfig::motion_draw = MotionDraw::kComposed): the controls
// queued since the last scan are split into runs, and each run is applied to a particle as one
// draw instead of one draw per control. An odometry model is equivariant under rigid motions
// (h(u, T s) = T h(u, s)), so the motion of a run in the frame of the pose it starts from is the
// same for every particle: its mean displacement d (x, y, theta) and, to first order in the
// control noise, its covariance C (Sigma <- J Sigma J^T + V M V^T control by control, at the
// run's mean path) are computed once per pass, and each particle moves by s <- s (+) (d + F n),
// F F^T = C, n three standard normals. Per particle and run that is three normals and one sine
// and cosine, where the draw per control takes two normals and a sine and cosine per control.
//
// A run ends after kRunMaxControls controls or once its heading variance reaches
// kRunHeadingVariance, where the first-order Gaussian stops being close to the draw per
// control (the banana of a long unobserved drive). docs/engine-config.md ("The motion draw")
// has the accuracy and speed measured against the draw per control.
//
// Only the odometry models (bailey-car, unicycle, ackermann; state (x, y, theta)) compose:
// the no-odometry walks carry per-particle velocities. Pure functions; the runs are value
// types, read concurrently by the blocks of a pass. Costs: compose_runs O(K) 3x3 products for
// K controls (one eigen-decomposition per run); apply_run O(lanes).
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

#include "engine/motion_batch.h"
#include "parallel/vector_math.h"

namespace fastslam::engine {

// A run holds at most this many controls (the motion stage's batch).
inline constexpr std::size_t kRunMaxControls = 64;
// A run ends once the variance of its heading reaches this (0.05 rad squared): the position's
// first-order error grows with the square of the heading's spread.
inline constexpr double kRunHeadingVariance = 0.05 * 0.05;

// One run: controls [first, first + count) of the pass, its mean displacement in the frame of
// its start pose and a factor F of the displacement's covariance (F F^T = C).
struct MotionRun {
  std::size_t first = 0;
  std::size_t count = 0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Matrix3d factor = Eigen::Matrix3d::Zero();
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
  MotionRun run;
  auto close = [&]() {
    run.mean = rel;
    // F = U sqrt(D): any factor of a symmetric positive semidefinite C (C may be singular: a
    // single control of two components spans a plane of the three).
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(0.5 * (cov + cov.transpose()));
    run.factor = eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).cwiseSqrt().asDiagonal();
    runs.push_back(run);
    rel.setZero();
    cov.setZero();
  };
  for (std::size_t k = 0; k < steps.size(); ++k) {
    if (run.count == 0) run.first = k;
    const typename Model::Control u(steps[k].u0, steps[k].u1);
    const double dt = steps[k].dt;
    const Eigen::Matrix3d j = model.jacobian_pose(rel, u, dt);
    cov = j * cov * j.transpose() + model.pose_noise(rel, u, dt, m);
    rel = model.predict(rel, u, dt);
    partial[k] = rel;
    ++run.count;
    if (run.count == kRunMaxControls || cov(2, 2) >= kRunHeadingVariance ||
        k + 1 == steps.size()) {
      close();
      run = MotionRun{};
    }
  }
}

// Moves lanes [0, lanes) of (x, y, theta) by one run: s <- s (+) (run.mean + run.factor n) with
// n = (n0[l], n1[l], n2[l]); the heading wrapped to (-pi, pi]. REQUIRES: |theta| <= pi and
// |run.mean[2] + the drawn heading noise| < pi (a run's heading spread is bounded above).
inline void apply_run(const MotionRun& run, std::size_t lanes, double* x, double* y, double* theta,
                      const double* n0, const double* n1, const double* n2) noexcept {
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
    double c = 0.0;
    double s = 0.0;
    parallel::sincos(theta[l], c, s);
    x[l] = madd(c, dx, madd(-s, dy, x[l]));
    y[l] = madd(s, dx, madd(c, dy, y[l]));
    double t = theta[l] + dt;
    t = t > kPi ? t - 2 * kPi : t;
    t = t <= -kPi ? t + 2 * kPi : t;
    theta[l] = t;
  }
}

}  // namespace fastslam::engine
