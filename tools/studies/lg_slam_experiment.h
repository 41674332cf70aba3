// The LG-SLAM convergence experiment (paper section 7, appendix B): FastSLAM 2.0 with M = 1 on
// linear-Gaussian SLAM (engine/lg_slam_filter.h), the errors of its map and pose against the truth
// over time, over several seeds, in two variants:
//   anchored  landmark 0 is known (its true position, covariance 0): the theorem's case; errors
//             are absolute;
//   relative  no landmark is known: the map is only defined up to a common offset (the paper:
//             "correct in relative terms, up to a fixed offset that uniformly applies to all
//             features"), so the errors are measured after removing the least-squares offset,
//             the mean of (estimate - truth) over the landmarks counted, from landmarks and pose.
// landmark_error = RMS over the mapped landmarks, the known one excluded (it is given), of the
// distance from estimate to truth; pose_error = the distance from the estimated pose to the true
// one. Before the first loop is complete only the landmarks seen so far are counted.
//
// The world: K landmarks evenly on a circle (radius 10 m by default), the robot's waypoints on a
// concentric circle (8 m), `steps_per_loop` per loop. Each step the control is the displacement
// from the true pose to the next waypoint, the true motion adds N(0, sigma_motion^2 I) (eq. 78),
// and every landmark within `sensor_range` of the true pose is observed, z = m - s +
// N(0, sigma_measurement^2 I) (eq. 77). The robot starts (exactly known) between landmarks 0
// and 1. Noise comes from the keyed streams (seed, step, *, Purpose::kSimulator); the filter's from
// (seed, step, particle, Purpose::kProposal); both variants of a seed see the same data.
//
// `fastslam experiment lg-slam` writes DIR/lg_slam.csv: header step,seed,variant,landmark_error,
// pose_error, one row per recorded step, seed and variant (`lg_slam_recorded_step`: every step up
// to 100, then about 50 per decade, and the last: for log-scale plots), and prints the mean errors
// over the seeds at steps 1, 10, 100, ... and the last.
//
// What to expect (measured, see the README): the map errors shrink as a power of the step, the
// relative ones about as 1/sqrt(t), the anchored ones much more slowly (the anchor's information
// reaches the other landmarks only through the pose, M = 1 keeps no correlations: roughly
// t^(-1/k) with k about the number of landmarks in view, as a linear analysis of the mean error
// predicts). The pose error does not go to zero: the theorem is about its expectation, while a
// single particle's pose is a draw from the proposal, whose spread is set by the noises.
//
// Ownership: plain values. Thread safety: thread-compatible; runs on the calling thread.
// Costs: O(seeds * steps * (M * observations + K)), about a microsecond per step at M = 1.
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
