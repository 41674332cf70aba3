// A FastSLAM runner for linear-Gaussian SLAM (paper section 7 and appendix B, the models of
// engine/lg_slam.h): the filter of the convergence theorem ("FastSLAM 2.0 with M = 1 converges
// in expectation to the correct map if one landmark's position is known") and its relative form.
// Known data association; each step draws every particle's pose from the motion prior folded
// with the observations (FastSLAM 2.0) or from the prior alone (1.0, the counter-example), then
// updates and initialises landmarks at the drawn pose; with M > 1 it resamples every step. A
// reference runner, not the scalable engine: maps are flat vectors copied at resampling. The
// step in full: docs/experiments.md ("The LG-SLAM runner, step by step").
//
// Ownership: the filter owns its particles; `step` borrows its observations for the call.
// Thread safety: thread-compatible; one thread; results are a pure function of the config, the
// seed and the inputs. Costs: `step` is O(M (n + K)) for n observations and K landmarks, and
// allocates O(K) scratch per step and O(M K) when resampling.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "engine/landmark_ekf.h"

namespace fastslam::engine {

enum class LgSlamProposal : std::uint8_t {
  kFastSlam2,  // motion prior refined by the observations (the theorem's filter)
  kMotion,     // FastSLAM 1.0: the motion prior alone
};

struct LgSlamConfig {
  std::size_t particles = 1;                                             // M >= 1
  std::size_t landmarks = 0;                                             // K >= 1; ids 0..K-1
  Eigen::Matrix2d motion_cov = 0.01 * Eigen::Matrix2d::Identity();       // P, symmetric PSD
  Eigen::Matrix2d measurement_cov = 0.01 * Eigen::Matrix2d::Identity();  // R, SPD
  LgSlamProposal proposal = LgSlamProposal::kFastSlam2;
  std::uint64_t seed = 1;
};

// One observation z = mu_id - s + noise (eq. 77) of landmark `id`.
struct LgSlamObservation {
  std::size_t id = 0;
  Eigen::Vector2d z = Eigen::Vector2d::Zero();
};

class LgSlamFilter {
 public:
  // Every particle starts at `initial_pose` (exactly known) with an empty map.
  // Throws std::invalid_argument naming the field when M or K is 0, P is not symmetric PSD or
  // R not symmetric positive definite.
  LgSlamFilter(const LgSlamConfig& config, const Eigen::Vector2d& initial_pose);

  // Makes landmark `id` known at `position` (covariance 0, never updated): the anchor of the
  // theorem. Throws std::invalid_argument if id >= K or the landmark is already mapped.
  void set_known_landmark(std::size_t id, const Eigen::Vector2d& position);

  // One control u and the observations made after it (any order, each landmark at most once).
  // Throws std::invalid_argument naming the first observation whose id is >= K, whose z is not
  // finite or whose landmark was already observed in this step, or when u is not finite, and
  // then changes nothing.
  void step(const Eigen::Vector2d& u, std::span<const LgSlamObservation> observations);

  const LgSlamConfig& config() const { return config_; }
  std::uint64_t steps() const { return step_; }
  std::size_t particles() const { return poses_.size(); }
  bool mapped(std::size_t id) const { return mapped_[id] != 0; }
  bool known(std::size_t id) const { return id == known_id_; }

  // Particle i's pose and its Gaussian of landmark id (zero until mapped). REQUIRES: i < M,
  // id < K.
  const Eigen::Vector2d& pose(std::size_t i) const { return poses_[i]; }
  const LandmarkGaussian& landmark(std::size_t i, std::size_t id) const {
    return maps_[i * config_.landmarks + id];
  }
  // The log-weights (normalised when M > 1: reset to -log M after each resampling; accumulated
  // for M = 1, where they do not matter).
  std::span<const double> log_weights() const { return log_weights_; }

  // The estimate: the particles' mean pose, and mean position of landmark id, weighted by the
  // normalised weights (M = 1: the particle's own). O(M).
  Eigen::Vector2d mean_pose() const;
  Eigen::Vector2d mean_landmark(std::size_t id) const;

 private:
  static constexpr std::size_t kNone = static_cast<std::size_t>(-1);

  void resample();
  std::vector<double> normalised_weights() const;

  LgSlamConfig config_;
  std::uint64_t step_ = 0;
  std::size_t known_id_ = kNone;
  std::vector<std::uint8_t> mapped_;    // per landmark: mapped by every particle
  std::vector<Eigen::Vector2d> poses_;  // per particle
  std::vector<LandmarkGaussian> maps_;  // particle i's landmark k at i * K + k
  std::vector<double> log_weights_;     // per particle
};

}  // namespace fastslam::engine
