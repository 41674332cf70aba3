// The landmark EKF of engine/landmark_ekf.h (evaluate_observation + apply_update, eq. 25, 31,
// 32) for one observation applied to many particles at once, over structure-of-arrays lanes, so
// that the compiler vectorises across particles. With known data association every particle of
// a block observes the same landmark slot at once: the filter gathers that landmark of each
// particle into lanes, calls `update_landmark_lanes`, and scatters the result back (the tree
// edits stay scalar).
//
// Each lane equals the scalar EKF up to rounding: atan2 and log are parallel/internal/vmath.h's
// (below 2 ulp and 1 ulp) instead of libm's, the sensor's sine and cosine (with an offset) too,
// and the bearing is wrapped in two exact steps; tests/engine/landmark_batch_test.cc bounds the
// difference. A lane whose inputs leave the vector path's domain (landmark at the sensor, a
// non-positive innovation determinant, a heading beyond a few turns, non-finite values) is
// recomputed by the scalar functions of engine/landmark_ekf.h.
//
// Determinism: a lane's result depends on that lane's inputs alone, not on `lanes` or the
// lane's position: the file is compiled without floating-point contraction (every product is
// rounded, fma only where vmath.h's madd says so), and whether a lane falls back depends on its
// inputs alone. So the filter stays bit-identical for any thread count and grain.
//
// Layout: every column holds `lanes` doubles; lane l is entry l of each. Columns must not
// overlap. Thread safety: pure function of its arguments; concurrent calls on disjoint columns
// are safe. Costs: O(lanes), about 120 flops, five divisions and a square root per lane; no
// allocation.
#pragma once

#include <cstddef>

#include <Eigen/Core>

#include "engine/measurement_model.h"

namespace fastslam::engine {

// Landmark means and covariances (upper triangle), read and written.
struct LandmarkLanes {
  double* x = nullptr;
  double* y = nullptr;
  double* sxx = nullptr;
  double* sxy = nullptr;
  double* syy = nullptr;
};

// Vehicle poses (heading in (-pi, pi]), read only.
struct PoseLanes {
  const double* x = nullptr;
  const double* y = nullptr;
  const double* theta = nullptr;
};

// For every lane l < lanes: the observation z = (range, bearing in (-pi, pi]) of landmark l
// from pose l under `sensor` with noise `r` (symmetric positive definite): adds ln N(v; 0, Q)
// (eq. 31) to log_w[l] unless log_w is null, then updates landmark l (eq. 25, Joseph form) as
// apply_update does.
void update_landmark_lanes(const RangeBearingModel& sensor, const Eigen::Matrix2d& r,
                           const Eigen::Vector2d& z, PoseLanes pose, LandmarkLanes lm,
                           double* log_w, std::size_t lanes);

}  // namespace fastslam::engine
