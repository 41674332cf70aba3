// The range-bearing measurement model z = g(mu, s) + eps, eps ~ N(0, R) (paper eq. 1), its
// Jacobians, and its inverse for landmark initialisation (eq. 69-70).
//
// The sensor sits at (offset.x, offset.y) in the vehicle frame and looks along the vehicle's
// heading plus offset.yaw. With d = mu - p(s), p(s) the sensor position in the world and
// q = d^T d: g(mu, s) = (sqrt(q), atan2(d_y, d_x) - theta - yaw), the bearing wrapped to
// (-pi, pi]. G_mu = dg/dmu (2x2) and G_s = dg/ds (2x3, differentiated through the offset).
// With a zero offset these are exactly ALGORITHM.md's matrices. Victoria Park's state already is
// the laser's pose, so it uses a zero offset; the offset stays general.
//
// `MeasurementLinearization` is the model-neutral result (z_hat, G_mu, G_s) that the landmark
// EKF (engine/landmark_ekf.h) and the FastSLAM 2.0 proposal (engine/proposal.h) consume; any
// model with the `MeasurementModel` shape (this one, engine/lg_slam.h) plugs into both.
// Bearing differences must go through `innovation`, which wraps them.
//
// Ownership: a value type of four doubles. Thread safety: const and pure, shareable freely.
// Cost: O(1), no allocation; `predict` and `linearize` are one sqrt and one atan2 (plus a sin
// and a cos when there is an offset).
#pragma once

#include <cmath>
#include <concepts>

#include <Eigen/Core>

#include "engine/angles.h"
#include "engine/pose.h"

namespace fastslam::engine {

// z_hat = g(mu, s) and the Jacobians at (mu, s), for a pose (or state) of PoseDim components.
template <int PoseDim>
struct MeasurementLinearization {
  Eigen::Vector2d z_hat;                     // predicted measurement, bearing wrapped
  Eigen::Matrix2d g_landmark;                // G_mu = dg/dmu
  Eigen::Matrix<double, 2, PoseDim> g_pose;  // G_s = dg/ds
};

// A measurement model usable by the landmark EKF and the proposal.
template <class M>
concept MeasurementModel = requires(const M& m, const Eigen::Vector2d& v,
                                    const typename M::PoseType& s) {
  { m.predict(v, s) } -> std::same_as<Eigen::Vector2d>;
  { m.linearize(v, s) } -> std::same_as<MeasurementLinearization<M::kPoseDim>>;
  { M::innovation(v, v) } -> std::same_as<Eigen::Vector2d>;
  { m.landmark_from(v, s) } -> std::same_as<Eigen::Vector2d>;
  { m.inverse_jacobian_measurement(v, s) } -> std::same_as<Eigen::Matrix2d>;
};

// Where the sensor sits on the vehicle: metres forward (x) and left (y), and its yaw (rad).
struct SensorOffset {
  double x = 0.0;
  double y = 0.0;
  double yaw = 0.0;
};

class RangeBearingModel {
 public:
  static constexpr int kPoseDim = 3;
  using PoseType = Pose;

  // A sensor at the vehicle's reference point, looking forward.
  RangeBearingModel() = default;
  // Throws std::invalid_argument unless every component of the offset is finite.
  explicit RangeBearingModel(const SensorOffset& offset);

  const SensorOffset& offset() const { return offset_; }

  // The sensor's position in the world for the vehicle pose s.
  Eigen::Vector2d sensor_position(const PoseType& s) const {
    if (!has_offset_) {
      return s.head<2>();
    }
    const double c = std::cos(s[2]);
    const double sn = std::sin(s[2]);
    return {s[0] + offset_.x * c - offset_.y * sn, s[1] + offset_.x * sn + offset_.y * c};
  }

  // g(mu, s) = (range, bearing), the bearing wrapped to (-pi, pi].
  Eigen::Vector2d predict(const Eigen::Vector2d& landmark, const PoseType& s) const {
    const Eigen::Vector2d d = landmark - sensor_position(s);
    return {std::sqrt(d.squaredNorm()), wrap_angle(std::atan2(d[1], d[0]) - s[2] - offset_.yaw)};
  }

  // z_hat, G_mu and G_s at (landmark, s), sharing the common terms.
  // REQUIRES: the landmark is not at the sensor (q > 0).
  MeasurementLinearization<3> linearize(const Eigen::Vector2d& landmark, const PoseType& s) const {
    return linearize_state<3>(landmark, s);
  }

  // The same for a longer state whose first three components are the pose (for example the
  // no-odometry state (x, y, theta, v, omega)); the extra columns of G_s are zero.
  template <int StateDim>
  MeasurementLinearization<StateDim> linearize_state(
      const Eigen::Vector2d& landmark, const Eigen::Matrix<double, StateDim, 1>& s) const {
    static_assert(StateDim >= 3);
    const Eigen::Vector3d pose = s.template head<3>();
    const Eigen::Vector2d p = sensor_position(pose);
    const double dx = landmark[0] - p[0];
    const double dy = landmark[1] - p[1];
    const double q = dx * dx + dy * dy;
    const double r = std::sqrt(q);
    const double inv_q = 1.0 / q;  // runs beside the sqrt; 1 / r = r / q saves a division
    const double inv_r = r * inv_q;
    // d(d)/d(theta) = -dp/dtheta = (p_y - y, -(p_x - x)); zero without an offset.
    const double ex = p[1] - pose[1];
    const double ey = pose[0] - p[0];
    MeasurementLinearization<StateDim> out;
    out.z_hat = {r, wrap_angle(std::atan2(dy, dx) - pose[2] - offset_.yaw)};
    out.g_landmark << dx * inv_r, dy * inv_r,  //
        -dy * inv_q, dx * inv_q;
    out.g_pose.setZero();
    out.g_pose(0, 0) = -dx * inv_r;
    out.g_pose(0, 1) = -dy * inv_r;
    out.g_pose(0, 2) = (dx * ex + dy * ey) * inv_r;
    out.g_pose(1, 0) = dy * inv_q;
    out.g_pose(1, 1) = -dx * inv_q;
    out.g_pose(1, 2) = (dx * ey - dy * ex) * inv_q - 1.0;
    return out;
  }

  Eigen::Matrix2d jacobian_landmark(const Eigen::Vector2d& landmark, const PoseType& s) const {
    return linearize(landmark, s).g_landmark;
  }
  Eigen::Matrix<double, 2, 3> jacobian_pose(const Eigen::Vector2d& landmark,
                                            const PoseType& s) const {
    return linearize(landmark, s).g_pose;
  }

  // z - z_hat with the bearing difference wrapped to (-pi, pi].
  static Eigen::Vector2d innovation(const Eigen::Vector2d& z, const Eigen::Vector2d& z_hat) {
    return {z[0] - z_hat[0], angle_diff(z[1], z_hat[1])};
  }

  // g^-1(z, s): the landmark position that produces z from pose s (eq. 69).
  Eigen::Vector2d landmark_from(const Eigen::Vector2d& z, const PoseType& s) const {
    const double angle = s[2] + offset_.yaw + z[1];
    return sensor_position(s) + z[0] * Eigen::Vector2d(std::cos(angle), std::sin(angle));
  }

  // d g^-1 / dz at (z, s); equals G_mu^-1 at the landmark g^-1(z, s), so the initial covariance
  // J R J^T is eq. 70's (G_mu^T R^-1 G_mu)^-1.
  Eigen::Matrix2d inverse_jacobian_measurement(const Eigen::Vector2d& z, const PoseType& s) const {
    const double angle = s[2] + offset_.yaw + z[1];
    const double c = std::cos(angle);
    const double sn = std::sin(angle);
    Eigen::Matrix2d j;
    j << c, -z[0] * sn,  //
        sn, z[0] * c;
    return j;
  }

  // d g^-1 / ds at (z, s).
  Eigen::Matrix<double, 2, 3> inverse_jacobian_pose(const Eigen::Vector2d& z,
                                                    const PoseType& s) const {
    const double angle = s[2] + offset_.yaw + z[1];
    const Eigen::Vector2d p = sensor_position(s);
    Eigen::Matrix<double, 2, 3> j;
    // dp/dtheta = (-(p_y - y), p_x - x).
    j << 1.0, 0.0, -(p[1] - s[1]) - z[0] * std::sin(angle),  //
        0.0, 1.0, (p[0] - s[0]) + z[0] * std::cos(angle);
    return j;
  }

 private:
  SensorOffset offset_;
  bool has_offset_ = false;  // offset x or y nonzero: the sensor position needs sin/cos
};

static_assert(MeasurementModel<RangeBearingModel>);

}  // namespace fastslam::engine
