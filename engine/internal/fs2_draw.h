// FastSLAM 2.0's pose draw under unknown association, for one particle: the landmarks the scan's
// association chose are folded into the proposal in scan order (eq. 61), then the state is drawn
// once from it (engine/proposal.h draw_state: without odometry the velocities keep their Gaussian
// given the pose). With none chosen the draw is from the motion prior, as eq. 68 for new
// landmarks. The returned `folded` is the chain of the folds' log-likelihoods plus observation
// j's "no landmark" score, log_unassociated[j] (ln p0, or ln u_j with a detection model:
// association.h), per new landmark: the weight factor under maximum likelihood (as with known
// ids).
// Thread safety: reads the map; a pure function otherwise. Costs: O(Z (log N + N^3)) for Z
// observations; no allocation.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "engine/association.h"
#include "engine/internal/scan_plan.h"
#include "engine/landmark_ekf.h"
#include "engine/measurement_model.h"
#include "engine/proposal.h"
#include "memory/landmark_tree.h"

namespace fastslam::engine::internal {

template <int N>
struct Fs2Draw {
  Eigen::Matrix<double, N, 1> state;  // the drawn state, heading wrapped
  Eigen::Matrix<double, N, N> rest;   // the covariance that outlives the scan (draw_state)
  double folded = 0.0;  // sum of the folds' ln-likelihoods and the new ones' log_unassociated
};

// `chosen[j]` is observation j's slot or kNewLandmark; `normals` N standard normals; the folds'
// terms under L + (weight_scale - 1) R (proposal.h).
template <int N>
Fs2Draw<N> fold_and_draw(const RangeBearingModel& sensor, const Eigen::Matrix2d& r,
                         std::span<const double> log_unassociated, const PoseGaussian<N>& prior,
                         const memory::LandmarkTree& map,
                         const std::vector<PlannedObservation>& scan,
                         std::span<const std::int64_t> chosen, const double* normals,
                         double weight_scale = 1.0) {
  PoseGaussian<N> proposal = prior;
  Fs2Draw<N> out;
  for (std::size_t j = 0; j < scan.size(); ++j) {
    if (chosen[j] == kNewLandmark) {
      out.folded += log_unassociated[j];
      continue;
    }
    const LandmarkGaussian lm = to_gaussian(map.at(static_cast<memory::Slot>(chosen[j])));
    ProposalObservation<N> terms = evaluate_proposal<N>(sensor, lm, proposal, scan[j].z, r);
    if (weight_scale != 1.0) scale_weight<N>(terms, r, weight_scale);
    out.folded += terms.log_likelihood;
    proposal = fold<N>(proposal, terms);
  }
  out.state = draw_state<N>(proposal, normals, out.rest);
  return out;
}

}  // namespace fastslam::engine::internal
