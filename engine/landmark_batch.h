// The per-observation math of a scan applied to many particles at once, over structure-of-arrays
// lanes, so that the compiler vectorises across particles: update_landmark_lanes (the landmark
// EKF of engine/landmark_ekf.h and the FastSLAM 1.0 weight term), fold_proposal_lanes and
// sample_pose_lanes (FastSLAM 2.0's proposal fold and pose draw, engine/proposal.h). Each lane
// equals the scalar functions up to rounding (atan2, log, sine and cosine are
// parallel/vector_math.h's; tests/engine/landmark_batch_test.cc bounds the difference); a lane
// whose inputs leave the vector path's domain is recomputed by the scalar functions. A lane's
// result depends on its own inputs alone (the file is compiled without contraction), so the
// filter is bit-identical for any thread count and grain. Every column holds `lanes` doubles;
// columns must not overlap. Thread safety: pure functions; concurrent calls on disjoint columns
// are safe. Costs: O(lanes) (O(N^3) a lane for an N x N proposal); no allocation.
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
// (eq. 31) to log_w[l] unless log_w is null, writes the squared Mahalanobis distance v^T Q^-1 v
// to mahalanobis2[l] unless that is null, then updates landmark l (eq. 25, Joseph form) as
// apply_update does.
void update_landmark_lanes(const RangeBearingModel& sensor, const Eigen::Matrix2d& r,
                           const Eigen::Vector2d& z, PoseLanes pose, LandmarkLanes lm,
                           double* log_w, std::size_t lanes, double* mahalanobis2 = nullptr);

// Pose proposals N(mean, cov) of state dimension N (heading = component 2, in (-pi, pi]):
// N mean columns and the N (N + 1) / 2 columns of the covariance's upper triangle, row by row
// ((0,0), (0,1), ..., (0,N-1), (1,1), ...), read and written.
template <int N>
struct ProposalLanes {
  double* mean[N] = {};
  double* cov[N * (N + 1) / 2] = {};
};

// Landmark means and covariances (upper triangle), read only.
struct ConstLandmarkLanes {
  const double* x = nullptr;
  const double* y = nullptr;
  const double* sxx = nullptr;
  const double* sxy = nullptr;
  const double* syy = nullptr;
};

// For every lane l < lanes: observation z of landmark l evaluated against proposal l
// (evaluate_proposal: linearised at the proposal's mean), its ln N(v; 0, L) added to log_w[l]
// (ln N(v; 0, L + (weight_scale - 1) R) with a weight scale, proposal.h), and the proposal
// replaced by the folded one (fold). N = 3 or 5.
template <int N>
void fold_proposal_lanes(const RangeBearingModel& sensor, const Eigen::Matrix2d& r,
                         const Eigen::Vector2d& z, ProposalLanes<N> proposal, ConstLandmarkLanes lm,
                         double* log_w, std::size_t lanes, double weight_scale = 1.0);

// For every lane l < lanes: state[k][l] = sample_pose(proposal l, &normals[N * l])[k], the
// heading wrapped. N = 3 or 5.
template <int N>
void sample_pose_lanes(ProposalLanes<N> proposal, const double* normals, double* const* state,
                       std::size_t lanes);

extern template void fold_proposal_lanes<3>(const RangeBearingModel&, const Eigen::Matrix2d&,
                                            const Eigen::Vector2d&, ProposalLanes<3>,
                                            ConstLandmarkLanes, double*, std::size_t, double);
extern template void fold_proposal_lanes<5>(const RangeBearingModel&, const Eigen::Matrix2d&,
                                            const Eigen::Vector2d&, ProposalLanes<5>,
                                            ConstLandmarkLanes, double*, std::size_t, double);
extern template void sample_pose_lanes<3>(ProposalLanes<3>, const double*, double* const*,
                                          std::size_t);
extern template void sample_pose_lanes<5>(ProposalLanes<5>, const double*, double* const*,
                                          std::size_t);

}  // namespace fastslam::engine
