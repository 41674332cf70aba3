// Everything a `Filter` (or the EKF-SLAM baseline, engine/ekf_slam.h) is built from: the
// algorithm, the particle count, the association mode, the motion and sensor models with their
// noises, the existence parameters, the resampling policy, the EKF's gates, the seed and the
// threads; and the name table of each enum a configuration holds (engine/enum_names.h). One
// plain struct, checked once by `validate(config)`, which names the first wrong field.
// Thread safety: value types. Costs: validation is O(1); docs/engine-config.md has the
// measurements behind the defaults.
#pragma once

#include <array>
#include <cstdint>
#include <numbers>
#include <string>
#include <string_view>

#include "engine/enum_names.h"
#include "engine/measurement_model.h"
#include "engine/motion_dispatch.h"
#include "parallel/resample.h"

namespace fastslam::engine {

enum class Algorithm : std::uint8_t {
  kFastSlam1,
  kFastSlam2,
  kEkf,  // EKF-SLAM over the pose and every landmark: engine/ekf_slam.h, not `Filter`
};
enum class Association : std::uint8_t {
  kKnown,                    // observations carry the landmark id (simulations, ground-truth tests)
  kMaximumLikelihood,        // eq. 64 (unknown association issue)
  kDataAssociationSampling,  // eq. 65 (unknown association issue)
};
template <>
struct EnumNames<Algorithm> {
  static constexpr std::string_view kWhat = "algorithm";
  static constexpr std::array<EnumName<Algorithm>, 3> kNames = {{
      {Algorithm::kFastSlam1, "fastslam1"},
      {Algorithm::kFastSlam2, "fastslam2"},
      {Algorithm::kEkf, "ekf"},
  }};
};

template <>
struct EnumNames<Association> {
  static constexpr std::string_view kWhat = "association";
  static constexpr std::array<EnumName<Association>, 3> kNames = {{
      {Association::kKnown, "known"},
      {Association::kMaximumLikelihood, "ml"},
      {Association::kDataAssociationSampling, "das"},
  }};
};

template <>
struct EnumNames<parallel::ResamplePolicy::When> {
  static constexpr std::string_view kWhat = "resampling policy";
  static constexpr std::array<EnumName<parallel::ResamplePolicy::When>, 2> kNames = {{
      {parallel::ResamplePolicy::When::kEveryStep, "every"},
      {parallel::ResamplePolicy::When::kEssBelowFraction, "neff"},
  }};
};

template <>
struct EnumNames<parallel::ResampleScheme> {
  static constexpr std::string_view kWhat = "resampling scheme";
  static constexpr std::array<EnumName<parallel::ResampleScheme>, 3> kNames = {{
      {parallel::ResampleScheme::kSystematic, "systematic"},
      {parallel::ResampleScheme::kStratified, "stratified"},
      {parallel::ResampleScheme::kMultinomial, "multinomial"},
  }};
};

struct SensorConfig {
  double sigma_range = 0.1;                             // m
  double sigma_bearing = 1.0 * std::numbers::pi / 180;  // rad
  SensorOffset offset;                                  // sensor pose on the vehicle
  double max_range = 30.0;                              // perceptual range (negative information)
  double field_of_view = std::numbers::pi;              // rad, centred on the sensor's heading
};

// Existence log-odds and negative information (eq. 73-75), unknown association only (with known
// ids every particle keeps every landmark); the defaults are table 1's counter form.
struct ExistenceConfig {
  bool negative_information = true;  // false: landmarks are never missed, never removed
  double initial = 1.0;              // log-odds of a new landmark
  double seen = 1.0;                 // l+ added when associated
  double missed = 1.0;               // l- subtracted when in view and not associated
  double remove_below = 0.0;         // removed when the log-odds fall below this
  // A landmark is provisional while its log-odds are below this: it takes part in association
  // and negative information like any other, but the estimate's map leaves it out. The default
  // (initial + 2 seen) confirms a landmark at its third association net of misses, so a false
  // alarm that is never detected again, or that leaves the view before it is missed often
  // enough to be removed, never reaches the map, nor does one that a second false alarm fell
  // near by chance (docs/association.md, "Existence and negative information").
  double confirm_at = 3.0;
  // A landmark counts as in view when its mean is within max_range - range_margin of the
  // sensor and inside the field of view: one at the edge is detected or not by where it truly
  // is, which its estimate does not know to better than its uncertainty.
  double range_margin = 1.0;  // m, >= 0
};

// How FastSLAM moves its particles between scans: control by control (1.0 draws at every
// control, 2.0 predicts its prior's mean and covariance at every control), or once per run of
// queued controls (engine/motion_run.h; odometry models only): 1.0 draws from the run's
// first-order Gaussian, 2.0's prior is the same up to rounding. kAuto composes wherever the
// motion composes and moves control by control elsewhere (the EKF, the no-odometry walks).
enum class MotionDraw : std::uint8_t {
  kEveryControl,  // 0: the bytes of a saved state written before the field existed
  kComposed,
  kAuto,
};

template <>
struct EnumNames<MotionDraw> {
  static constexpr std::string_view kWhat = "motion draw";
  static constexpr std::array<EnumName<MotionDraw>, 3> kNames = {{
      {MotionDraw::kEveryControl, "control"},
      {MotionDraw::kComposed, "composed"},
      {MotionDraw::kAuto, "auto"},
  }};
};

// Unknown data association (ml, das): gating, and the search for candidates.
struct AssociationConfig {
  // A candidate is considered only when its squared Mahalanobis distance v^T Q^-1 v (FastSLAM
  // 2.0: v^T L^-1 v, eq. 60) is at most this: by default chi-square with 2 dof at 99.999%, wide
  // enough that p0, not the gate, decides between a known landmark and a new one (the gate
  // bounds the search; docs/engine-config.md).
  double gate = 23.025850929940457;
  // Candidates come from a disc query of the particle's spatial index around the landmark
  // position the observation implies; its radius is this factor times the radius the gate
  // implies under linearisation (a margin for the nonlinearity of range-bearing), >= 1.
  double search_scale = 1.5;
};

// The sensor's detection model for unknown association (ml, das): each landmark in view is
// detected with `probability`, and false alarms arrive as a Poisson process of
// `clutter_density` per m² of the footprint per scan. An observation that takes no landmark is
// then a new landmark (p0) or a false alarm, and a landmark explains it only by being detected,
// so "no landmark" scores ln((p0 + kappa(z)) / P_D) against a candidate's ln p (docs/
// association.md), where kappa(z) = clutter_density * r is the false-alarm density in range
// and bearing (polar area element r dr dphi). The defaults (1, 0) leave ln p0 alone, bit for bit.
struct DetectionConfig {
  double probability = 1.0;      // P_D, in (0, 1]
  double clutter_density = 0.0;  // false alarms per m² per scan, >= 0; 0: no clutter model
};

// Loop closure for unknown association (ml, das), by matching the particle's map against
// itself. Once resampling has left every particle with one drifted history, an old landmark seen
// again lies outside every particle's gate and is started anew: each particle maps it twice and
// the loop never closes (docs/association.md, "Loop closure"). When a landmark is confirmed,
// the particle pairs its recent landmarks (confirmed, associated within `min_age` steps, within
// the sensor's range) with its old ones (confirmed, not associated for `min_age` steps): two
// pair when each is the other's only confirmed neighbour within `separation` metres, or, when
// they lie farther apart than that, within `reach`; maps denser than the separation never pair.
// When there are two pairs or more, all agree on one rigid motion (their distances within the
// pairs' uncertainty) and that motion turns by at most `max_turn`, the particle's pose and its
// recent landmarks move by the least-squares motion onto the old ones; the twins then lie
// together, association takes one of each and negative information removes the other. reach 0:
// off, and every run is bit for bit what it was.
struct LoopClosureConfig {
  double reach = 15.0;           // m, >= 0: the largest drift a loop closes over
  std::uint64_t min_age = 2000;  // steps (controls and scans) that separate old from recent
  // m, >= 0: twins at most this far apart must be alone within it, farther ones within `reach`
  // (at least `reach` when larger or 0: one radius).
  double separation = 10.0;
  double max_turn = 0.2;  // rad, > 0: the largest heading drift a loop closes over
  // Squared Mahalanobis distance, >= 0 (0: never): two confirmed landmarks that are candidates of
  // one observation, and whose means lie within this of each other under their two covariances,
  // are one landmark mapped twice (twins that a closure brought together, or a landmark restarted
  // beside itself), and the map update keeps one of them. Off by default: on the webmap it halves
  // the false landmarks at no cost in pose, but on maps of distinct landmarks a metre or two apart
  // it joins some (docs/association.md, "Twin merging"); 9.21 is chi-square's 99 % for 2 degrees.
  double merge_gate = 0.0;
};

// EKF-SLAM (Algorithm::kEkf) with maximum-likelihood association: gates on the squared
// Mahalanobis distance d2 = v^T S^-1 v of an observation to a landmark (chi-square with 2 degrees
// of freedom when the association is right). An observation takes the nearest landmark (smallest
// d2) if d2 < gate_accept, becomes a new landmark if d2 > gate_new for every landmark, and is
// dropped in between (ambiguous). REQUIRES: 0 < gate_accept <= gate_new.
struct EkfConfig {
  double gate_accept = 5.991;  // chi2(2) 95% quantile
  double gate_new = 13.816;    // chi2(2) 99.9% quantile
  // Joint compatibility branch and bound (Neira and Tardos 2001) instead of the greedy nearest
  // neighbour: the largest set of pairings that is jointly compatible at gate_accept's confidence.
  bool joint_compatibility = false;
};

struct FilterConfig {
  Algorithm algorithm = Algorithm::kFastSlam1;
  std::uint32_t particles = 100;
  Association association = Association::kKnown;
  MotionConfig motion;
  SensorConfig sensor;
  // ln p0: the log-likelihood of "a new landmark" (eq. 64-65, 71); unknown association only.
  double log_new_landmark = -6.0;
  AssociationConfig gating;
  ExistenceConfig existence;
  parallel::ResamplePolicy resample{parallel::ResamplePolicy::When::kEssBelowFraction, 0.75,
                                    parallel::ResampleScheme::kSystematic};
  std::uint64_t seed = 1;
  unsigned threads = 0;  // 0: every core
  // Particles per parallel task: a pass deals whole groups of 8 particles to about
  // particles / grain tasks; up to `grain` particles run on the calling thread alone, unless
  // the pass is heavy (split_seconds). The default is measured: docs/engine-config.md.
  std::size_t grain = 128;
  // A pass (the controls since the last scan, and the scan) whose work took longer than this
  // on the last pass is split into at least one block per thread, whatever the grain
  // (docs/engine-config.md). Decides only the split, never a result.
  double split_seconds = 100e-6;
  // Keep the weighted-mean pose after every control for `Filter::take_trajectory` (costs a
  // store per particle per control and a reduction per control).
  bool record_trajectory = false;
  // kComposed: FastSLAM with an odometry model only (validate refuses the rest). In the padding
  // after record_trajectory, so that a saved state's later fields keep their offsets.
  MotionDraw motion_draw = MotionDraw::kAuto;
  EkfConfig ekf;  // Algorithm::kEkf only
  // The initial pose of every particle (x, y, theta; v, omega for kBrownian; v, kappa for
  // kBrownianCurvature).
  double initial_pose[5] = {0, 0, 0, 0, 0};
  // Last, so that a saved state's earlier fields keep their offsets (engine/internal/state_io).
  DetectionConfig detection;       // FastSLAM with ml or das (the EKF baseline ignores it)
  LoopClosureConfig loop_closure;  // FastSLAM with ml or das (the EKF baseline ignores it)
  // The lag-1 correlation of one landmark's measurement errors from scan to scan, in [0, 1): 0
  // for independent errors. A systematic error (a sensor's mounting, the odometry's drift
  // between sightings) repeats while a landmark stays in view, so n sightings carry the
  // information of only n (1 - rho) / (1 + rho) independent ones. FastSLAM 2.0 then scores its
  // associations and weights with the sensor noise R (1 + rho) / (1 - rho) (proposal.h
  // weight_scale), and keeps R for its proposal and landmark updates. A run's innovations
  // estimate it (tools/scripts/innovation_correlation.py, docs/engine-config.md). FastSLAM 2.0
  // only.
  double error_correlation = 0.0;
};

// Throws std::invalid_argument naming the first unusable field (zero particles, a non-positive
// or non-finite noise, wheelbase or range, an association the build does not support, ...).
void validate(const FilterConfig& config);

// The draw a filter of this configuration runs: motion_draw, with kAuto resolved (kComposed for
// FastSLAM with an odometry model, kEveryControl otherwise).
MotionDraw resolved_motion_draw(const FilterConfig& config);

// The names of the tables above (metrics.json, log headers, the command line).
constexpr std::string_view to_string(Algorithm algorithm) { return enum_name(algorithm); }
constexpr std::string_view to_string(Association association) { return enum_name(association); }
constexpr std::string_view to_string(MotionKind kind) { return enum_name(kind); }
constexpr std::string_view to_string(MotionDraw draw) { return enum_name(draw); }

}  // namespace fastslam::engine
