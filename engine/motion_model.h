// Vehicle motion models s_t = h(u_t, s_{t-1}) + delta, delta ~ N(0, P) (paper eq. 2): Bailey's
// car, a unicycle, an Ackermann car with its sensor ahead of the rear axle, and two no-odometry
// random walks (eq. 79-81). Each has the `MotionModel` shape: predict (noise-free, heading
// wrapped), jacobian_pose, jacobian_control, pose_noise P = V M V^T (singular when the control
// has fewer dimensions than the state; never invert it), and sample (the motion under a control
// perturbed by normals the caller draws; models own no generator). Models are small value
// types; every method is const and pure, safe from any number of threads; O(1) per call, no
// allocation.
#pragma once

#include <cmath>
#include <concepts>

#include <Eigen/Core>

#include "engine/angles.h"
#include "engine/pose.h"

namespace fastslam::engine {

// The shape shared by the models (see the file comment). CRTP base: a model provides predict,
// jacobian_pose and jacobian_control; pose_noise and sample are derived from them.
template <class Derived, int StateDim, int ControlDim>
class MotionModelBase {
 public:
  static constexpr int kStateDim = StateDim;
  static constexpr int kControlDim = ControlDim;
  using State = Eigen::Matrix<double, StateDim, 1>;
  using Control = Eigen::Matrix<double, ControlDim, 1>;
  using StateJacobian = Eigen::Matrix<double, StateDim, StateDim>;
  using ControlJacobian = Eigen::Matrix<double, StateDim, ControlDim>;
  using StateCovariance = Eigen::Matrix<double, StateDim, StateDim>;
  using ControlCovariance = Eigen::Matrix<double, ControlDim, ControlDim>;
  // True for the models whose "control" is a nominally zero increment (no odometry): the filter
  // and the EKF pass zero whatever the log's controls say.
  static constexpr bool kNoOdometry = false;

  // P = V M V^T with V = jacobian_control(s, u, dt). REQUIRES: M symmetric positive semidefinite.
  StateCovariance pose_noise(const State& s, const Control& u, double dt,
                             const ControlCovariance& control_cov) const {
    const ControlJacobian v = self().jacobian_control(s, u, dt);
    const ControlJacobian vm = v * control_cov;
    StateCovariance p = vm * v.transpose();
    return 0.5 * (p + p.transpose());  // exactly symmetric
  }

  // M = diag(sigmas^2), the control covariance `sample` draws from.
  static ControlCovariance control_covariance(const Control& sigmas) {
    return sigmas.cwiseAbs2().asDiagonal();
  }

  // h(u + sigmas .* n, s) for the kControlDim standard normals at `normals`.
  // REQUIRES: normals points at kControlDim readable doubles.
  State sample(const State& s, const Control& u, double dt, const Control& sigmas,
               const double* normals) const {
    const Control perturbed = u + sigmas.cwiseProduct(Eigen::Map<const Control>(normals));
    return self().predict(s, perturbed, dt);
  }

 private:
  const Derived& self() const { return static_cast<const Derived&>(*this); }
};

// A motion model of the common shape.
template <class M>
concept MotionModel = requires(const M& m, const typename M::State& s, const typename M::Control& u,
                               double dt, const typename M::ControlCovariance& cov,
                               const double* normals) {
  { m.predict(s, u, dt) } -> std::same_as<typename M::State>;
  { m.jacobian_pose(s, u, dt) } -> std::same_as<typename M::StateJacobian>;
  { m.jacobian_control(s, u, dt) } -> std::same_as<typename M::ControlJacobian>;
  { m.pose_noise(s, u, dt, cov) } -> std::same_as<typename M::StateCovariance>;
  { m.sample(s, u, dt, u, normals) } -> std::same_as<typename M::State>;
};

// Bailey's simulator car: control (V, G) = (speed m/s, steering rad, measured from the heading),
//   x += V dt cos(G + theta), y += V dt sin(G + theta), theta += V dt sin(G) / wheelbase.
class BaileyCarModel : public MotionModelBase<BaileyCarModel, 3, 2> {
 public:
  BaileyCarModel() = default;
  // Throws std::invalid_argument unless wheelbase is finite and > 0.
  explicit BaileyCarModel(double wheelbase);

  double wheelbase() const { return wheelbase_; }

  State predict(const State& s, const Control& u, double dt) const {
    const double vdt = u[0] * dt;
    const double heading = u[1] + s[2];
    return {s[0] + vdt * std::cos(heading), s[1] + vdt * std::sin(heading),
            wrap_angle(s[2] + vdt * std::sin(u[1]) / wheelbase_)};
  }

  StateJacobian jacobian_pose(const State& s, const Control& u, double dt) const {
    const double vdt = u[0] * dt;
    const double heading = u[1] + s[2];
    StateJacobian j = StateJacobian::Identity();
    j(0, 2) = -vdt * std::sin(heading);
    j(1, 2) = vdt * std::cos(heading);
    return j;
  }

  ControlJacobian jacobian_control(const State& s, const Control& u, double dt) const {
    const double vdt = u[0] * dt;
    const double c = std::cos(u[1] + s[2]);
    const double sn = std::sin(u[1] + s[2]);
    ControlJacobian j;
    j << dt * c, -vdt * sn,  //
        dt * sn, vdt * c,    //
        dt * std::sin(u[1]) / wheelbase_, vdt * std::cos(u[1]) / wheelbase_;
    return j;
  }

 private:
  double wheelbase_ = 4.0;  // metres (Bailey's WHEELBASE)
};

// A unicycle: control (v, omega) = (forward speed m/s, turn rate rad/s); the Euler step of
// paper eq. 81: x += v dt cos(theta), y += v dt sin(theta), theta += omega dt.
class UnicycleModel : public MotionModelBase<UnicycleModel, 3, 2> {
 public:
  State predict(const State& s, const Control& u, double dt) const {
    const double vdt = u[0] * dt;
    return {s[0] + vdt * std::cos(s[2]), s[1] + vdt * std::sin(s[2]), wrap_angle(s[2] + u[1] * dt)};
  }

  StateJacobian jacobian_pose(const State& s, const Control& u, double dt) const {
    const double vdt = u[0] * dt;
    StateJacobian j = StateJacobian::Identity();
    j(0, 2) = -vdt * std::sin(s[2]);
    j(1, 2) = vdt * std::cos(s[2]);
    return j;
  }

  ControlJacobian jacobian_control(const State& s, const Control& /*u*/, double dt) const {
    ControlJacobian j;
    j << dt * std::cos(s[2]), 0.0,  //
        dt * std::sin(s[2]), 0.0,   //
        0.0, dt;
    return j;
  }
};

// Where an Ackermann car's sensor and odometry sit, in metres. No defaults for a particular car
// (a data-set reader supplies them); l must be set.
struct AckermannGeometry {
  double a = 0.0;  // sensor ahead of the rear axle
  double b = 0.0;  // sensor to the left of the centre line
  double l = 0.0;  // wheelbase, > 0
  double h = 0.0;  // encoder wheel (rear left) to the left of the centre line, >= 0
};

// An Ackermann car (Guivant and Nebot); the state is the SENSOR point's pose (x, y, phi). Control
// (ve, alpha) = (rear-left encoder speed m/s, front steering angle rad, + = left):
//   vc = ve / (1 - tan(alpha) H / L)                     (encoder -> rear-axle centre)
//   x   += dt (vc cos(phi) - (vc / L) tan(alpha) (a sin(phi) + b cos(phi)))
//   y   += dt (vc sin(phi) + (vc / L) tan(alpha) (a cos(phi) - b sin(phi)))
//   phi += dt (vc / L) tan(alpha)
// REQUIRES: |tan(alpha)| < L / H so vc is finite.
class AckermannModel : public MotionModelBase<AckermannModel, 3, 2> {
 public:
  // Throws std::invalid_argument unless every length is finite, l > 0 and h >= 0.
  explicit AckermannModel(const AckermannGeometry& geometry);

  const AckermannGeometry& geometry() const { return g_; }

  State predict(const State& s, const Control& u, double dt) const {
    const double t = std::tan(u[1]);
    const double vc = u[0] / (1.0 - t * g_.h / g_.l);
    const double k = vc * t / g_.l;  // phi_dot
    const double c = std::cos(s[2]);
    const double sn = std::sin(s[2]);
    return {s[0] + dt * (vc * c - k * (g_.a * sn + g_.b * c)),
            s[1] + dt * (vc * sn + k * (g_.a * c - g_.b * sn)), wrap_angle(s[2] + dt * k)};
  }

  StateJacobian jacobian_pose(const State& s, const Control& u, double dt) const {
    const double t = std::tan(u[1]);
    const double vc = u[0] / (1.0 - t * g_.h / g_.l);
    const double k = vc * t / g_.l;
    const double c = std::cos(s[2]);
    const double sn = std::sin(s[2]);
    StateJacobian j = StateJacobian::Identity();
    j(0, 2) = dt * (-vc * sn - k * (g_.a * c - g_.b * sn));
    j(1, 2) = dt * (vc * c - k * (g_.a * sn + g_.b * c));
    return j;
  }

  ControlJacobian jacobian_control(const State& s, const Control& u, double dt) const {
    const double t = std::tan(u[1]);
    const double sec2 = 1.0 + t * t;
    const double denom = 1.0 - t * g_.h / g_.l;
    const double vc = u[0] / denom;
    // d vc / d(ve, alpha) and d k / d(ve, alpha), with k = vc tan(alpha) / L.
    const double dvc_dve = 1.0 / denom;
    const double dvc_dal = u[0] * (g_.h / g_.l) * sec2 / (denom * denom);
    const double dk_dve = dvc_dve * t / g_.l;
    const double dk_dal = (dvc_dal * t + vc * sec2) / g_.l;
    const double c = std::cos(s[2]);
    const double sn = std::sin(s[2]);
    const double ex = g_.a * sn + g_.b * c;  // x lever
    const double ey = g_.a * c - g_.b * sn;  // y lever
    ControlJacobian j;
    j << dt * (dvc_dve * c - dk_dve * ex), dt * (dvc_dal * c - dk_dal * ex),   //
        dt * (dvc_dve * sn + dk_dve * ey), dt * (dvc_dal * sn + dk_dal * ey),  //
        dt * dk_dve, dt * dk_dal;
    return j;
  }

 private:
  AckermannGeometry g_;
};

// How the heading turns in the no-odometry models below: the fifth state component c, walked
// like the speed v, gives the turn rate theta_dot = rate(v, c).
struct TurnRateWalk {  // c = omega (rad/s), theta_dot = omega (paper eq. 79-81)
  static constexpr bool kRateDependsOnSpeed = false;
  static double rate(double /*v*/, double c) { return c; }
};
struct CurvatureWalk {  // c = kappa (1/m), theta_dot = v kappa: no turning while standing still
  static constexpr bool kRateDependsOnSpeed = true;
  static double rate(double v, double c) { return v * c; }
};

// No odometry (paper section 9.2, eq. 79-81): the state carries the velocities,
// (x, y, theta, v, c), c as `Turn` says (above). The "control" is the increment (dv, dc),
// nominally zero:
//   v' = v + dv, c' = c + dc                                                   (eq. 80)
//   x += v' cos(theta) dt, y += v' sin(theta) dt, theta += rate(v', c') dt     (eq. 81)
// so sample(s, Control::Zero(), dt, (sigma1, sigma2), n) is exactly eq. 80-81 (for TurnRateWalk;
// CurvatureWalk walks the curvature of a car's rear axle, whose heading cannot turn at v = 0).
// The sigmas are per step, as in the paper; for a random walk in continuous time pass
// sigma * sqrt(dt). The filter ignores the logged controls for these models (kNoOdometry).
template <class Turn>
class BrownianModel : public MotionModelBase<BrownianModel<Turn>, 5, 2> {
  using Base = MotionModelBase<BrownianModel<Turn>, 5, 2>;

 public:
  using typename Base::Control;
  using typename Base::ControlJacobian;
  using typename Base::State;
  using typename Base::StateJacobian;
  static constexpr bool kNoOdometry = true;

  State predict(const State& s, const Control& u, double dt) const {
    const double v = s[3] + u[0];
    const double c = s[4] + u[1];
    State out;
    out << s[0] + v * std::cos(s[2]) * dt, s[1] + v * std::sin(s[2]) * dt,
        wrap_angle(s[2] + Turn::rate(v, c) * dt), v, c;
    return out;
  }

  StateJacobian jacobian_pose(const State& s, const Control& u, double dt) const {
    const double v = s[3] + u[0];
    const double cs = std::cos(s[2]);
    const double sn = std::sin(s[2]);
    StateJacobian j = StateJacobian::Identity();
    j(0, 2) = -v * sn * dt;
    j(0, 3) = cs * dt;
    j(1, 2) = v * cs * dt;
    j(1, 3) = sn * dt;
    if constexpr (Turn::kRateDependsOnSpeed) {
      j(2, 3) = (s[4] + u[1]) * dt;  // d(v' kappa')/dv = kappa'
      j(2, 4) = v * dt;
    } else {
      j(2, 4) = dt;
    }
    return j;
  }

  ControlJacobian jacobian_control(const State& s, const Control& u, double dt) const {
    ControlJacobian j = ControlJacobian::Zero();
    j(0, 0) = std::cos(s[2]) * dt;
    j(1, 0) = std::sin(s[2]) * dt;
    if constexpr (Turn::kRateDependsOnSpeed) {
      j(2, 0) = (s[4] + u[1]) * dt;
      j(2, 1) = (s[3] + u[0]) * dt;
    } else {
      j(2, 1) = dt;
    }
    j(3, 0) = 1.0;
    j(4, 1) = 1.0;
    return j;
  }
};

// The paper's model: state (x, y, theta, v, omega).
using BrownianVelocityModel = BrownianModel<TurnRateWalk>;
// Speed and path curvature: state (x, y, theta, v, kappa).
using BrownianCurvatureModel = BrownianModel<CurvatureWalk>;

static_assert(MotionModel<BaileyCarModel>);
static_assert(MotionModel<UnicycleModel>);
static_assert(MotionModel<AckermannModel>);
static_assert(MotionModel<BrownianVelocityModel>);
static_assert(MotionModel<BrownianCurvatureModel>);

}  // namespace fastslam::engine
