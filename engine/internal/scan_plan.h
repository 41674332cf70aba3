// Input checks and the scan plan: what `predict`, `observe` and `set_map` refuse, and, for a
// valid scan, each observation as every particle will process it (known association: the map
// slot of its landmark and whether the scan creates it). Nothing here changes filter state; the
// caller commits the plan (merging `new_slots` into its table) only once the pass has run.
// Thread safety: pure functions. Costs: plan_scan O(Z) expected (hash tables), check_map O(N);
// both allocate their results.
#pragma once

#include <algorithm>
#include <cstdint>
#include <span>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "engine/filter.h"
#include "memory/landmark_tree.h"

namespace fastslam::engine::internal {

// A queued odometry sample, with the step number that keys its random draws. Saved as raw bytes
// (engine/internal/state_io.h): no padding.
struct PendingControl {
  double u0 = 0.0;
  double u1 = 0.0;
  double dt = 0.0;
  std::uint64_t step = 0;
};

// One observation of a scan as every particle processes it: the measurement (range, wrapped
// bearing) and, with known ids, the landmark's slot and id and whether this scan creates it.
struct PlannedObservation {
  Eigen::Vector2d z;
  memory::Slot slot = 0;
  std::uint64_t id = 0;
  bool is_new = false;
};

// Known association: landmark id -> its slot, the same in every particle's map.
using KnownSlots = std::unordered_map<std::int64_t, memory::Slot>;

struct ScanPlan {
  std::vector<PlannedObservation> observations;
  KnownSlots new_slots;  // known association: the ids this scan adds
};

// Throws std::invalid_argument unless dt >= 0 and every value is finite.
void check_control(const Control& control, double dt);

// Throws std::invalid_argument unless `time` is finite and, once the clock was set (`timed`), not
// before `clock`.
void check_time(double time, double clock, bool timed);

// Validates `scan` (finite values, range > 0; known ids: id >= 0 and not repeated; unknown: fewer
// than kObservationsPerScanLimit observations) and plans it. Throws std::invalid_argument naming
// the first bad observation.
ScanPlan plan_scan(std::span<const Observation> scan, Association association,
                   const KnownSlots& known);

// The largest eigenvalue of the measurement noise `r` mapped to the plane at `range`: the
// landmark covariance of eq. 70 has eigenvalues sigma_r^2 and (range sigma_phi)^2.
inline double measurement_variance(const Eigen::Matrix2d& r, double range) {
  return std::max(r(0, 0), range * range * r(1, 1));
}

struct MapCheck {
  KnownSlots known;             // known ids: id -> slot (input order); empty otherwise
  double variance_bound = 0.0;  // max(`bound`, every landmark covariance's largest eigenvalue)
};

// Validates a prior map for Filter::set_map (finite positions within 1e150, symmetric positive
// definite covariances, finite log-odds; known ids distinct and < 2^63). Throws
// std::invalid_argument naming the first bad landmark.
MapCheck check_map(std::span<const MapLandmark> landmarks, bool known_ids, double bound);

}  // namespace fastslam::engine::internal
