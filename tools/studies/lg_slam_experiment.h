// The LG-SLAM convergence experiment (paper section 7, appendix B): FastSLAM 2.0 with M = 1 on
// linear-Gaussian SLAM (engine/lg_slam_filter.h), the map and pose errors against the truth
// over time and seeds, anchored (landmark 0 known: the theorem's case) and relative (errors
// after removing the mean offset of the estimate). The world, the error definitions and the
// results are in docs/experiments.md (lg-slam).
//
// Ownership: plain values. Thread safety: thread-compatible; runs on the calling thread.
// Costs: O(seeds * steps * (M * observations + K)) time; memory O(recorded rows).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "engine/lg_slam_filter.h"

namespace fastslam::tools {

struct LgSlamWorldConfig {
  std::size_t landmarks = 6;        // K >= 1
  double landmark_radius = 10.0;    // m
  double path_radius = 8.0;         // m
  std::size_t steps_per_loop = 40;  // >= 3
  double sensor_range = 12.0;       // m, > 0 (2 or 3 of the 6 default landmarks in view)
  double sigma_motion = 0.1;        // m per axis per step, >= 0
  double sigma_measurement = 0.1;   // m per axis, > 0
};
// Throws std::invalid_argument naming the first field out of range.
void validate(const LgSlamWorldConfig& world);

// The truth of one seed, one step at a time.
class LgSlamSimulator {
 public:
  // Throws as validate(world).
  LgSlamSimulator(const LgSlamWorldConfig& world, std::uint64_t seed);

  const std::vector<Eigen::Vector2d>& landmarks() const { return landmarks_; }
  const Eigen::Vector2d& pose() const { return pose_; }  // the true pose after the last step
  std::uint64_t steps() const { return step_; }

  // Moves one step; fills the control given to the filter and the observations made after it
  // (landmarks in range, ascending ids). Allocates only to grow `observations`.
  void step(Eigen::Vector2d& control, std::vector<engine::LgSlamObservation>& observations);

 private:
  LgSlamWorldConfig world_;
  std::uint64_t seed_;
  std::uint64_t step_ = 0;
  std::vector<Eigen::Vector2d> landmarks_;
  Eigen::Vector2d pose_;
};

struct LgSlamErrors {
  double landmark = 0.0;    // m, RMS over the counted landmarks (NaN when none is counted)
  double pose = 0.0;        // m
  std::size_t counted = 0;  // landmarks counted: mapped and not known
};
// The errors of `filter`'s estimate (mean_pose, mean_landmark) against the truth; with
// `remove_offset` after removing the mean offset of the counted landmarks (see the file comment).
// REQUIRES: truth_landmarks.size() == filter.config().landmarks.
LgSlamErrors lg_slam_errors(const engine::LgSlamFilter& filter,
                            std::span<const Eigen::Vector2d> truth_landmarks,
                            const Eigen::Vector2d& truth_pose, bool remove_offset);

enum class LgSlamVariant : std::uint8_t { kAnchored, kRelative };
std::string_view to_string(LgSlamVariant variant);

// One run: a filter on `seed`'s data for `steps` steps; calls `on_step(step, errors)` after each.
// `proposal` is the filter's (kMotion only to show what the theorem does not cover).
template <class OnStep>
void run_lg_slam(const LgSlamWorldConfig& world, LgSlamVariant variant, std::uint64_t seed,
                 std::uint64_t steps, std::size_t particles, engine::LgSlamProposal proposal,
                 OnStep&& on_step);

struct LgSlamExperimentOptions {
  std::string out;           // directory for lg_slam.csv (created)
  std::uint64_t seeds = 10;  // seeds first_seed .. first_seed + seeds - 1
  std::uint64_t first_seed = 1;
  std::uint64_t steps = 0;    // 0: the default (100000, or 2000 with tiny)
  std::size_t particles = 1;  // M
  bool tiny = false;          // a small run for tests: at most 3 seeds, 2000 steps by default
  LgSlamWorldConfig world;
};

struct LgSlamRow {
  std::uint64_t step = 0;
  std::uint64_t seed = 0;
  LgSlamVariant variant = LgSlamVariant::kAnchored;
  double landmark_error = 0.0;
  double pose_error = 0.0;
};

// Whether step t (from 1) of a run of `last` steps is written: t <= 100, t == last, or t is the
// first step of one of 50 equal slices of a decade (floor(50 log10 t) > floor(50 log10 (t - 1))).
bool lg_slam_recorded_step(std::uint64_t t, std::uint64_t last);

// The rows of the experiment (recorded steps only), ordered by seed, then variant (anchored
// first), then step.
// Throws std::invalid_argument for 0 seeds, 0 particles or an invalid world.
std::vector<LgSlamRow> run_lg_slam_experiment(const LgSlamExperimentOptions& options);

// Writes the CSV (header, then "%llu,%llu,%s,%.9g,%.9g" rows). Throws std::runtime_error naming
// the path when it cannot be written.
void write_lg_slam_csv(const std::string& path, std::span<const LgSlamRow> rows);

// `fastslam experiment lg-slam`: runs, writes out/lg_slam.csv, prints the mean errors over the
// seeds at steps 1, 10, 100, ... and the last, and the time taken. Returns the exit code.
int run_lg_slam_command(const LgSlamExperimentOptions& options);

// ---- implementation of the template

template <class OnStep>
void run_lg_slam(const LgSlamWorldConfig& world, LgSlamVariant variant, std::uint64_t seed,
                 std::uint64_t steps, std::size_t particles, engine::LgSlamProposal proposal,
                 OnStep&& on_step) {
  LgSlamSimulator sim(world, seed);
  engine::LgSlamConfig config;
  config.particles = particles;
  config.landmarks = world.landmarks;
  config.motion_cov = world.sigma_motion * world.sigma_motion * Eigen::Matrix2d::Identity();
  config.measurement_cov =
      world.sigma_measurement * world.sigma_measurement * Eigen::Matrix2d::Identity();
  config.proposal = proposal;
  config.seed = seed;
  engine::LgSlamFilter filter(config, sim.pose());
  if (variant == LgSlamVariant::kAnchored) filter.set_known_landmark(0, sim.landmarks()[0]);
  Eigen::Vector2d u;
  std::vector<engine::LgSlamObservation> observations;
  for (std::uint64_t t = 1; t <= steps; ++t) {
    sim.step(u, observations);
    filter.step(u, observations);
    on_step(t, lg_slam_errors(filter, sim.landmarks(), sim.pose(),
                              variant == LgSlamVariant::kRelative));
  }
}

}  // namespace fastslam::tools
