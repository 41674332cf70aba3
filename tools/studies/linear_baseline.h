// The linear-copy baseline of the paper's section 8 (fig. 14-15): a plain FastSLAM 1.0 whose
// particles each own a flat std::vector of landmarks, copied whole when resampling duplicates a
// particle, with ML association by a linear scan of each map. It shares the engine's math
// (motion sampling with the keyed streams, the gate, evaluate_observation, Joseph update,
// negative information, ML with mutual exclusion) and resamples (systematic) after every scan.
// Supported: FastSLAM 1.0, ML, Bailey's car; the constructor refuses anything else. It moves
// its particles control by control under motion_draw 'auto' too (an explicit 'composed' is
// refused).
// docs/scaling.md compares it with the tree engine.
//
// Ownership: owns its particles and their maps; `observe` and `set_map` borrow their spans for
// the call. Thread safety: thread-compatible; runs on the calling thread (config.threads is
// ignored). Costs (M particles, N landmarks per map, Z observations): `predict` O(M); `observe`
// O(M (N + Z k)) plus O(M N) for the copies at resampling; memory M maps of N * 64 bytes.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "engine/association.h"
#include "engine/filter.h"
#include "engine/filter_config.h"
#include "engine/measurement_model.h"
#include "engine/motion_model.h"
#include "memory/landmark_tree.h"

namespace fastslam::tools {

struct LinearStatistics {
  std::uint64_t controls = 0, scans = 0, observations = 0;
  std::uint64_t weight_resets = 0;  // scans whose every weight was zero (reset to uniform)
  std::uint64_t map_copies = 0;     // whole maps copied by resampling
  std::uint64_t landmarks_created = 0, landmarks_removed = 0;
  double predict_seconds = 0.0, associate_seconds = 0.0, update_seconds = 0.0,
         resample_seconds = 0.0;
};

class LinearFastSlam {
 public:
  // Throws std::invalid_argument as engine::validate(config), and unless the algorithm is
  // FastSLAM 1.0, the association ML and the motion model Bailey's car.
  explicit LinearFastSlam(const engine::FilterConfig& config);

  // Every particle's map becomes a copy of `landmarks` (ids and log-odds kept, last_seen 0).
  // Throws std::invalid_argument (and changes nothing) for a non-finite position, a covariance
  // that is not symmetric positive definite or non-finite log-odds, naming the landmark.
  void set_map(std::span<const engine::MapLandmark> landmarks);

  // Samples one control step for every particle. Throws std::invalid_argument (and changes
  // nothing) unless dt >= 0 and the values are finite.
  void predict(const engine::Control& control, double dt);

  // Associates, updates every particle's map and weight, then resamples. Throws
  // std::invalid_argument (and changes nothing) for a non-finite value or a range <= 0.
  void observe(std::span<const engine::Observation> scan);

  // The weighted mean pose (x, y, circular mean of theta).
  engine::Pose mean_pose() const;

  // Sum over particles of map.capacity() * sizeof(memory::Landmark).
  std::int64_t live_bytes() const;

  std::size_t particles() const { return particles_.size(); }
  const std::vector<memory::Landmark>& map(std::size_t particle) const {
    return particles_[particle].map;
  }
  const LinearStatistics& statistics() const { return stats_; }

 private:
  struct Particle {
    engine::Pose pose = engine::Pose::Zero();
    double log_weight = 0.0;
    std::vector<memory::Landmark> map;
  };
  // The scan's gating constants, from the config.
  struct ScanGate {
    bool negative = false;  // negative information applies
    double view_range = 0.0, half_fov = 0.0, gate = 0.0, scale2 = 0.0;
  };
  ScanGate scan_gate() const;
  // Fills candidates_ and in_view_ for `p` (the positions `at` and disc radii `radius2` per
  // observation are scratch), then assignment_ by ML; returns the log-weight increment.
  double associate(const Particle& p, std::span<const Eigen::Vector2d> z, const ScanGate& g,
                   std::span<Eigen::Vector2d> at, std::span<double> radius2);
  // Updates the associated landmarks, applies negative information to the rest in view and
  // adds the new ones.
  void update_map(Particle& p, std::span<const Eigen::Vector2d> z, std::uint64_t scan_step);
  // Systematic resampling with the streams of (seed, scan_step); duplicates copy their map.
  void resample_after(std::uint64_t scan_step);
  double measurement_variance(double range) const;

  engine::FilterConfig config_;
  engine::BaileyCarModel motion_;
  engine::RangeBearingModel sensor_;
  Eigen::Matrix2d r_;
  std::vector<Particle> particles_;
  double landmark_variance_bound_ = 0.0;  // as the engine's: bounds the candidate search radius
  std::uint64_t step_ = 0;                // controls and scans so far: keys the random streams
  LinearStatistics stats_;
  // Scratch reused across particles.
  std::vector<engine::AssociationCandidate> candidates_;
  std::vector<std::int64_t> assignment_;
  std::vector<std::uint32_t> in_view_;
  std::vector<std::uint32_t> touched_;
  std::vector<std::uint32_t> doomed_;
};

}  // namespace fastslam::tools
