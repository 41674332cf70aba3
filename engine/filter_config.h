// Everything a `Filter` (or the EKF-SLAM baseline, engine/ekf_slam.h) is built from: the
// algorithm, the particle count, the association mode, the motion and sensor models with their
// noises, the existence (log-odds) parameters, the resampling policy, the EKF's gates, the seed
// and the threads. One plain struct, validated once by `validate(config)`, which names the first
// field that is wrong.
//
// Thread safety: value types. Costs: validation is O(1).
#pragma once

#include <cstdint>
#include <numbers>
#include <string>
#include <string_view>

#include "engine/measurement_model.h"
#include "engine/motion_model.h"
#include "parallel/resample.h"

namespace fastslam::engine {

enum class Algorithm : std::uint8_t {
  kFastSlam1,
  kFastSlam2,
  kEkf,  // EKF-SLAM over the pose and every landmark: engine/ekf_slam.h, not `Filter`
};
enum class Association : std::uint8_t {
  kKnown,  // observations carry the landmark id (simulations, ground-truth tests)
  kMaximumLikelihood,          // eq. 64 (unknown association issue)
  kDataAssociationSampling,    // eq. 65 (unknown association issue)
};
enum class MotionKind : std::uint8_t {
  kBaileyCar,     // control (V, G): speed and steering from the heading; Bailey's simulator
  kUnicycle,      // control (v, omega)
  kVictoriaPark,  // control (encoder speed, steering); the state is the laser's pose
  kBrownian,      // no odometry (eq. 79-81): controls carry no information, only dt
  // No odometry, speed and path curvature walked (engine/motion_model.h BrownianCurvatureModel:
  // theta_dot = v kappa, the rear axle of a car); controls carry no information, only dt.
  kBrownianCurvature,
};

// Whether the model ignores the controls and carries its velocities in the state (x, y, theta,
// v, omega or kappa): kBrownian and kBrownianCurvature.
constexpr bool without_odometry(MotionKind kind) noexcept {
  return kind == MotionKind::kBrownian || kind == MotionKind::kBrownianCurvature;
}

struct MotionConfig {
  MotionKind kind = MotionKind::kBaileyCar;
  double wheelbase = 4.0;           // kBaileyCar
  VictoriaParkGeometry geometry;    // kVictoriaPark
  // Standard deviations of the control noise (per control component: speed m/s and steering
  // rad for the cars, v and omega for the unicycle; for kBrownian the per-step increments of v
  // and omega, eq. 80; for kBrownianCurvature those of v (m/s) and kappa (1/m)).
  double sigma_control[2] = {0.3, 3.0 * std::numbers::pi / 180};
};

struct SensorConfig {
  double sigma_range = 0.1;                              // m
  double sigma_bearing = 1.0 * std::numbers::pi / 180;   // rad
  SensorOffset offset;                                   // sensor pose on the vehicle
  double max_range = 30.0;                               // perceptual range (negative information)
  double field_of_view = std::numbers::pi;               // rad, centred on the sensor's heading
};

// Existence log-odds and negative information (eq. 73-75), unknown association only (with known
// ids every particle keeps every landmark); the defaults are table 1's counter form.
struct ExistenceConfig {
  bool negative_information = true;  // false: landmarks are never missed, never removed
  double initial = 1.0;       // log-odds of a new landmark
  double seen = 1.0;          // l+ added when associated
  double missed = 1.0;        // l- subtracted when in view and not associated
  double remove_below = 0.0;  // removed when the log-odds fall below this
  // A landmark counts as in view when its mean is within max_range - range_margin of the
  // sensor and inside the field of view: one at the edge is detected or not by where it truly
  // is, which its estimate does not know to better than its uncertainty.
  double range_margin = 1.0;  // m, >= 0
};

// Unknown data association (ml, das): gating, and the search for candidates.
struct AssociationConfig {
  // A candidate is considered only when its squared Mahalanobis distance v^T Q^-1 v (FastSLAM
  // 2.0: v^T L^-1 v, eq. 60) is at most this: by default chi-square with 2 dof at 99.999%, wide
  // enough that p0, not the gate, decides between a known landmark and a new one at the default
  // noise and p0 (the gate bounds the search; a narrower one turns loop closures into new
  // landmarks: on webmap, FS2 ML pose RMSE 9.1 m at 13.8, 7.6 m at 23 and above).
  double gate = 23.025850929940457;
  // Candidates come from a disc query of the particle's spatial index around the landmark
  // position the observation implies; its radius is this factor times the radius the gate
  // implies under linearisation (a margin for the nonlinearity of range-bearing), >= 1.
  double search_scale = 1.5;
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
  unsigned threads = 0;      // 0: every core
  // Particles per parallel task (a pass deals whole groups of 8 particles to about
  // particles / grain tasks, see engine/filter.cc; up to `grain` particles run on the calling
  // thread alone, unless the pass is heavy: see split_seconds). 128 amortises the per-block
  // setup of the vectorised control loop (about 0.4 us; webmap FS1, M = 100, one thread:
  // 37.5 ms at 16, 33.2 ms at 128), keeps filters too small to gain from a second thread
  // inline, and gives each thread several tasks from M = 1000 up.
  std::size_t grain = 128;
  // A pass (the controls since the last scan, and the scan) whose work took longer than this
  // on the last pass is split into at least one block per thread, whatever the grain: Victoria
  // Park's association (~0.5 ms a pass at M = 100) gains from a second thread, webmap's
  // ~12 us passes lose to the dispatch. Decides only the split, never a result.
  double split_seconds = 100e-6;
  // Keep the weighted-mean pose after every control for `Filter::take_trajectory` (costs a
  // store per particle per control and a reduction per control).
  bool record_trajectory = false;
  EkfConfig ekf;  // Algorithm::kEkf only
  // The initial pose of every particle (x, y, theta; v, omega for kBrownian; v, kappa for
  // kBrownianCurvature).
  double initial_pose[5] = {0, 0, 0, 0, 0};
};

// Throws std::invalid_argument naming the first unusable field (zero particles, a non-positive
// or non-finite noise, wheelbase or range, an association the build does not support, ...).
void validate(const FilterConfig& config);

std::string_view to_string(Algorithm algorithm);
std::string_view to_string(Association association);
std::string_view to_string(MotionKind kind);

}  // namespace fastslam::engine
