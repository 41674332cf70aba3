#include "engine/internal/known_update.h"

#include <algorithm>
#include <limits>

#include "engine/landmark_batch.h"
#include "engine/landmark_ekf.h"
#include "engine/motion_batch.h"
#include "engine/proposal.h"

namespace fastslam::engine::internal {
namespace {

// Draws each lane's state from its folded proposal into `state` and leaves in the covariance
// slots what outlives the scan: nothing (N = 3), or the velocities' Gaussian given the pose
// (N > 3: only the pose is drawn, normals from 3 on zeroed; covariance F22 F22^T, draw_state).
template <int N>
void draw_block(ProposalLanes<N> proposal, const double* draws, double* const* state,
                PoseCovariances& covariances, std::size_t begin, std::size_t count,
                KnownScratch& scratch) {
  covariances.clear(begin, count);
  if constexpr (N > 3) {
    scratch.pose_only.assign(draws, draws + N * count);
    for (std::size_t l = 0; l < count; ++l) std::fill_n(&scratch.pose_only[l * N + 3], N - 3, 0.0);
    sample_pose_lanes<N>(proposal, scratch.pose_only.data(), state, count);
    for (std::size_t l = 0; l < count; ++l) {
      Eigen::Matrix<double, N, N> cov;
      for (int row = 0, e = 0; row < N; ++row) {
        for (int c = row; c < N; ++c, ++e) cov(row, c) = cov(c, row) = proposal.cov[e][l];
      }
      covariances.at<N>(begin + l) = rest_given_pose<N>(psd_factor<N>(cov));
    }
  } else {
    sample_pose_lanes<N>(proposal, draws, state, count);
  }
}

}  // namespace

template <int N>
void propose_block_known(const KnownInput& in, const std::vector<PlannedObservation>& scan,
                         memory::ParticleStore& store, PoseCovariances& covariances,
                         std::size_t begin, std::size_t end, const double* draws,
                         KnownScratch& scratch) {
  constexpr int E = N * (N + 1) / 2;
  const std::size_t count = end - begin;
  // Columns: N means, E covariance entries, landmark x, y, sxx, sxy, syy, the log-likelihood.
  scratch.columns.assign((N + E + 6) * count, 0.0);
  auto column = [&](int c) { return scratch.columns.data() + static_cast<std::size_t>(c) * count; };
  double* const state[5] = {store.x().data() + begin, store.y().data() + begin,
                            store.theta().data() + begin, store.v().data() + begin,
                            store.omega().data() + begin};
  ProposalLanes<N> proposal;
  for (int k = 0; k < N; ++k) {
    proposal.mean[k] = column(k);
    std::copy_n(state[k], count, proposal.mean[k]);
  }
  for (int e = 0; e < E; ++e) proposal.cov[e] = column(N + e);
  covariances.load_upper<N>(begin, count, proposal.cov);
  double* lm[5];
  for (int k = 0; k < 5; ++k) lm[k] = column(N + E + k);
  double* const log_w = column(N + E + 5);
  for (const PlannedObservation& o : scan) {
    if (o.is_new) continue;
    for (std::size_t l = 0; l < count; ++l) {
      const memory::Landmark& stored = store.map(begin + l).at(o.slot);
      lm[0][l] = stored.x;
      lm[1][l] = stored.y;
      lm[2][l] = stored.sxx;
      lm[3][l] = stored.sxy;
      lm[4][l] = stored.syy;
    }
    fold_proposal_lanes<N>(*in.sensor, in.r, o.z, proposal, {lm[0], lm[1], lm[2], lm[3], lm[4]},
                           log_w, count, in.weight_scale);
  }
  draw_block<N>(proposal, draws, state, covariances, begin, count, scratch);
  double* const log_weight = store.log_weight().data();
  for (std::size_t l = 0; l < count; ++l) log_weight[begin + l] += log_w[l];
}

template <bool kWeigh>
void update_block_known(const KnownInput& in, const std::vector<PlannedObservation>& scan,
                        memory::ParticleStore& store, std::size_t begin, std::size_t end,
                        ScanRecords& records, KnownScratch& scratch) {
  const std::size_t count = end - begin;
  const std::size_t lanes = padded_lanes(count);
  // Columns: pose x, y, theta; landmark x, y, sxx, sxy, syy; the scan's log-likelihood sum; the
  // observation's squared Mahalanobis distance.
  scratch.columns.resize(10 * lanes);
  scratch.edited.resize(count);
  double* col[10];
  for (int c = 0; c < 10; ++c) col[c] = scratch.columns.data() + c * lanes;
  const double* const pose_col[3] = {store.x().data(), store.y().data(), store.theta().data()};
  for (int c = 0; c < 3; ++c) {
    std::copy_n(pose_col[c] + begin, count, col[c]);
    std::fill(col[c] + count, col[c] + lanes, 0.0);
  }
  // Padding lanes: a landmark 1 m ahead with a unit covariance (any valid input; unused).
  constexpr double kPadding[5] = {1.0, 0.0, 1.0, 0.0, 1.0};
  for (int c = 0; c < 5; ++c) std::fill(col[3 + c] + count, col[3 + c] + lanes, kPadding[c]);
  std::fill_n(col[8], lanes, 0.0);
  const PoseLanes poses{col[0], col[1], col[2]};
  const LandmarkLanes lm{col[3], col[4], col[5], col[6], col[7]};
  const auto step_now = static_cast<std::int64_t>(in.scan_step);
  for (std::size_t j = 0; j < scan.size(); ++j) {
    const PlannedObservation& o = scan[j];
    if (o.is_new) {
      for (std::size_t l = 0; l < count; ++l) {
        records.mahalanobis2(j, begin + l) = std::numeric_limits<double>::infinity();
        const Pose pose(col[0][l], col[1][l], col[2][l]);
        memory::Landmark stored;
        store_gaussian(initialize_landmark(*in.sensor, pose, o.z, in.r), stored);
        stored.log_odds = in.existence.initial;
        stored.id = o.id;
        stored.last_seen = step_now;
        store.map(begin + l).insert(stored, 0.0f);  // unindexed: no extent
      }
      continue;
    }
    for (std::size_t l = 0; l < count; ++l) {
      memory::Landmark& stored = store.map(begin + l).edit_unindexed(o.slot);
      scratch.edited[l] = &stored;
      lm.x[l] = stored.x;
      lm.y[l] = stored.y;
      lm.sxx[l] = stored.sxx;
      lm.sxy[l] = stored.sxy;
      lm.syy[l] = stored.syy;
    }
    update_landmark_lanes(*in.sensor, in.r, o.z, poses, lm, kWeigh ? col[8] : nullptr, lanes,
                          col[9]);
    std::copy_n(col[9], count, &records.mahalanobis2(j, begin));
    for (std::size_t l = 0; l < count; ++l) {
      memory::Landmark& stored = *scratch.edited[l];
      stored.x = lm.x[l];
      stored.y = lm.y[l];
      stored.sxx = lm.sxx[l];
      stored.sxy = lm.sxy[l];
      stored.syy = lm.syy[l];
      stored.log_odds += in.existence.seen;
      stored.last_seen = step_now;
    }
  }
  if constexpr (kWeigh) {
    double* const log_weight = store.log_weight().data();
    for (std::size_t l = 0; l < count; ++l) log_weight[begin + l] += col[8][l];
  }
}

template void propose_block_known<3>(const KnownInput&, const std::vector<PlannedObservation>&,
                                     memory::ParticleStore&, PoseCovariances&, std::size_t,
                                     std::size_t, const double*, KnownScratch&);
template void propose_block_known<5>(const KnownInput&, const std::vector<PlannedObservation>&,
                                     memory::ParticleStore&, PoseCovariances&, std::size_t,
                                     std::size_t, const double*, KnownScratch&);
template void update_block_known<true>(const KnownInput&, const std::vector<PlannedObservation>&,
                                       memory::ParticleStore&, std::size_t, std::size_t,
                                       ScanRecords&, KnownScratch&);
template void update_block_known<false>(const KnownInput&, const std::vector<PlannedObservation>&,
                                        memory::ParticleStore&, std::size_t, std::size_t,
                                        ScanRecords&, KnownScratch&);

}  // namespace fastslam::engine::internal
