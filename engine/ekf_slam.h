// EKF-SLAM, the baseline the paper compares FastSLAM against (section 2 and the experiments of
// sections 7-9): one Gaussian over the vehicle pose and every landmark, with a dense covariance.
//
// The state is [pose; m_1; ...; m_N]: the pose is (x, y, theta), or (x, y, theta, v, omega) for
// MotionKind::kBrownian ((x, y, theta, v, kappa) for kBrownianCurvature), and each landmark adds
// its (x, y). It is built from the same
// `FilterConfig` as `Filter` (algorithm = Algorithm::kEkf) and uses the same models:
//   predict   the motion model of config.motion (engine/motion_model.h), linearised: the pose
//             mean goes through h(u, s), its covariance through F P F^T + V M V^T with
//             M = diag(sigma_control^2); the pose-landmark block becomes F P_xm. Landmarks do
//             not move, so only the pose rows and columns change.
//   observe   the range-bearing model with the sensor offset (engine/measurement_model.h). Each
//             associated observation is one EKF update, in scan order, each linearised at the
//             state left by the previous one: S = H P H^T + R, K = P H^T S^-1, x += K v,
//             P -= K S K^T. H has only five nonzero columns (x, y, theta and the landmark), so
//             P H^T costs O(n) and the covariance update one rank-2 pass over P.
//             Observations of unseen landmarks are added after the updates, by the inverse model
//             m = g^-1(z, s), with cov(m, .) = J_s P_{s,.} and cov(m, m) = J_s P_ss J_s^T +
//             J_z R J_z^T (J_s, J_z: the inverse model's Jacobians w.r.t. pose and measurement).
// Association: config.association == kKnown uses the observations' ids; kMaximumLikelihood gates
// on the squared Mahalanobis distance d2 = v^T S^-1 v against every landmark (at the state
// before the scan): each observation takes the landmark of smallest d2 if d2 < ekf.gate_accept,
// pairs being taken greedily by increasing d2 so that no landmark is used twice in one scan
// (mutual exclusion); an observation with d2 > ekf.gate_new for every landmark starts a new
// landmark, and one in between is dropped. With ekf.joint_compatibility the greedy choice is
// replaced by joint compatibility branch and bound (JCBB, Neira and Tardos 2001): the largest set
// of pairs whose innovations are jointly compatible (their joint d2 below the chi-square quantile
// of 2k degrees of freedom at the accept gate's confidence), searched over the individually
// compatible pairs, at most 10^5 hypotheses per scan. kDataAssociationSampling is refused (it
// needs particles). Landmarks are never removed (the EKF keeps no existence estimate).
//
// The covariance is stored as the lower triangle of a dense matrix (the upper triangle is not
// kept up to date), so it is exactly symmetric by construction; `covariance()` returns the full
// matrix.
//
// Bad input (NaN or infinite values, a negative or zero range, dt < 0, a missing or repeated id
// in known-association mode) throws std::invalid_argument naming what is wrong and leaves the
// state exactly as it was. A numerical failure (an innovation covariance that is not positive
// definite) throws std::runtime_error.
//
// Ownership: owns its state; `observe` borrows the scan for the call only.
// Thread safety: thread-compatible: one call at a time; single-threaded inside (deterministic).
// Costs, n = 3 + 2N (5 + 2N without odometry) for N landmarks: `predict` O(N) time, no allocation
// but the trajectory; `observe` O(n^2) per associated observation (the rank-2 covariance update:
// about n^2 flops and one pass over n^2 / 2 doubles), plus O(N) per new landmark (amortised:
// the covariance grows by 1.25x when full, an O(n^2) copy) and, for ML association,
// O(Z N log(Z N)) to score and sort the candidate pairs of a scan of Z observations (JCBB:
// exponential in Z in the worst case, bounded by its hypothesis budget, O(k^3) each); `estimate`
// O(N); memory 8 n^2 bytes (about 32 MB at N = 1000, 128 MB at N = 2000).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "engine/filter.h"
#include "engine/filter_config.h"

namespace fastslam::engine {

// What the association did with the observations of every scan so far.
struct EkfAssociationCounts {
  std::uint64_t updated = 0;  // associated with a landmark in the map: one EKF update each
  std::uint64_t created = 0;  // started a new landmark
  std::uint64_t dropped = 0;  // ML only: between the gates, or its landmarks went to better pairs
};

class EkfSlam {
 public:
  // Throws std::invalid_argument as validate(config), and unless config.algorithm is kEkf.
  explicit EkfSlam(const FilterConfig& config);
  ~EkfSlam();
  EkfSlam(EkfSlam&&) noexcept;
  EkfSlam& operator=(EkfSlam&&) noexcept;
  EkfSlam(const EkfSlam&) = delete;
  EkfSlam& operator=(const EkfSlam&) = delete;

  const FilterConfig& config() const noexcept;

  // One odometry sample of duration dt, applied at once. Throws std::invalid_argument (and
  // changes nothing) unless dt >= 0 and every value is finite.
  void predict(const Control& control, double dt);

  // Associates and applies one scan. Throws std::invalid_argument (and changes nothing) for a
  // bad observation.
  void observe(std::span<const Observation> scan);

  // mean_pose = best_pose = the EKF mean; best_particle 0, effective_sample_size 1; the map in
  // landmark order (slot = index) with the 2x2 marginal covariances, id = the observations' id
  // in known mode and the landmark's index under ML, log_odds 0.
  Estimate estimate() const;

  // Counters and times (update_seconds = observe_wall_seconds = time in observe); no resampling;
  // live_nodes 0 and live_bytes = the bytes of the dense mean and covariance.
  FilterStatistics statistics() const;
  EkfAssociationCounts association_counts() const noexcept;

  // The mean pose after every control since the last call; empty unless
  // config.record_trajectory.
  std::vector<TrajectoryPoint> take_trajectory();

  // The dense state, for tests and tools: the pose dimension (3 or 5), the landmark count, the
  // mean and the full symmetric covariance (copies, O(n) and O(n^2)).
  int pose_dim() const noexcept;
  std::size_t landmark_count() const noexcept;
  Eigen::VectorXd mean() const;
  Eigen::MatrixXd covariance() const;

  // Makes room for `landmarks` landmarks in all, so the covariance does not grow by copying.
  void reserve(std::size_t landmarks);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace fastslam::engine
