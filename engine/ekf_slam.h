// EKF-SLAM, the baseline the paper compares FastSLAM against: one Gaussian over the pose (3, or 5
// without odometry) and every landmark, dense covariance (lower triangle kept), built from the
// same `FilterConfig` as `Filter` (algorithm kEkf) and the same models; known or ML association
// (greedy nearest with mutual exclusion, or JCBB), DAS refused. docs/engine-config.md describes
// the updates. Bad input throws std::invalid_argument and changes nothing; a non-positive-definite
// innovation covariance throws std::runtime_error. Owns its state; thread-compatible,
// single-threaded inside. Costs, n = 3 + 2N: predict O(N), observe O(n^2) per update plus
// O(Z N log(Z N)) for ML scoring (JCBB bounded by 10^5 hypotheses a scan), memory 8 n^2 bytes.
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
  // As Filter's: sets the clock (Estimate::time); refused when it goes backwards.
  void predict(const Control& control, double dt, double time);

  // Associates and applies one scan. Throws std::invalid_argument (and changes nothing) for a
  // bad observation.
  void observe(std::span<const Observation> scan);
  void observe(std::span<const Observation> scan, double time);

  // mean_pose = best_pose = the EKF mean, pose_covariance its pose block; best_particle 0,
  // effective_sample_size 1; the clock as Filter's; the last scan's associations (known ids: the
  // distance at the state its update saw; ML: as the choice scored it before the scan's
  // updates; a new landmark's or a discarded observation's: to the nearest landmark, which
  // for a discarded one lies between the gates); the map in
  // landmark order (slot = index) with the 2x2 marginal covariances, id = the observations' id
  // in known mode and the landmark's index under ML, log_odds 0.
  Estimate estimate(EstimateMap map = EstimateMap::kCopy) const;
  // The last scan's report, as Estimate::associations: O(1).
  const std::vector<ObservationAssociation>& last_associations() const noexcept;

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
