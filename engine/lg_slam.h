// The linear-Gaussian SLAM models of the paper's convergence result (section 7, eq. 77-78):
// positions only, g(mu, s) = mu - s and h(u, s) = u + s. A robot in Cartesian space with a
// noise-free compass that measures landmark offsets along the axes.
//
// They have the same shapes as the range-bearing model and the car models, so the landmark EKF
// (engine/landmark_ekf.h) and the FastSLAM 2.0 proposal (engine/proposal.h, N = 2) run on them
// unchanged; with linear models every linearisation is exact, which makes LG-SLAM an exact oracle
// for that code (the Kalman filter of the joint Gaussian gives the same numbers).
//
// Thread safety: stateless, pure. Cost: a few additions, no allocation, all inline.
#pragma once

#include <Eigen/Core>

#include "engine/measurement_model.h"
#include "engine/motion_model.h"

namespace fastslam::engine {

// z = g(mu, s) + eps = mu - s + eps (eq. 77). Pose (x, y); no angles, nothing wrapped.
class LinearGaussianMeasurement {
 public:
  static constexpr int kPoseDim = 2;
  using PoseType = Eigen::Vector2d;

  Eigen::Vector2d predict(const Eigen::Vector2d& landmark, const PoseType& s) const {
    return landmark - s;
  }
  MeasurementLinearization<2> linearize(const Eigen::Vector2d& landmark, const PoseType& s) const {
    return {landmark - s, Eigen::Matrix2d::Identity(), -Eigen::Matrix2d::Identity()};
  }
  static Eigen::Vector2d innovation(const Eigen::Vector2d& z, const Eigen::Vector2d& z_hat) {
    return z - z_hat;
  }
  Eigen::Vector2d landmark_from(const Eigen::Vector2d& z, const PoseType& s) const { return z + s; }
  Eigen::Matrix2d inverse_jacobian_measurement(const Eigen::Vector2d& /*z*/,
                                               const PoseType& /*s*/) const {
    return Eigen::Matrix2d::Identity();
  }
};

// s_t = h(u, s_{t-1}) + delta = u + s_{t-1} + delta (eq. 78); dt is not used.
class LinearGaussianMotion : public MotionModelBase<LinearGaussianMotion, 2, 2> {
 public:
  State predict(const State& s, const Control& u, double /*dt*/) const { return s + u; }
  StateJacobian jacobian_pose(const State& /*s*/, const Control& /*u*/, double /*dt*/) const {
    return StateJacobian::Identity();
  }
  ControlJacobian jacobian_control(const State& /*s*/, const Control& /*u*/, double /*dt*/) const {
    return ControlJacobian::Identity();
  }
};

static_assert(MeasurementModel<LinearGaussianMeasurement>);
static_assert(MotionModel<LinearGaussianMotion>);

}  // namespace fastslam::engine
