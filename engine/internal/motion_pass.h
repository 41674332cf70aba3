// The motion stage of a pass: the queued controls applied to one block of particles. The block's
// states (and, for FastSLAM 2.0, the upper triangles of its state covariances) are copied into
// the thread's lane columns, padded to whole groups of kMotionLanes, carried through every
// control by the vectorised kernels of engine/motion_batch.h (1.0: sample_block with the keyed
// motion normals, taken from the ahead window where it holds them; 2.0: predict_block), and
// copied back. When the trajectory is recorded it adds the block's weighted sums after every
// control (TrajectorySums::add). Under the composed motion (odometry models) the pass's runs
// (engine/motion_run.h, composed once per pass) move each lane once per run: 1.0 by three
// normals of stream (seed, the run's last step, particle, kMotionRun and kMotionRunHeading),
// 2.0 by the run's mean and covariance; the sums are added at the runs' starts and ends only
// (the recorder moves a run's start to the points inside it).
// Thread safety: concurrent calls on disjoint blocks with distinct scratch are safe. Costs:
// O(count K) for K queued controls; no allocation once the scratch has grown.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "engine/internal/motion_normals_ahead.h"
#include "engine/internal/pose_covariance.h"
#include "engine/internal/scan_plan.h"
#include "engine/internal/trajectory_recorder.h"
#include "engine/motion_batch.h"
#include "engine/motion_run.h"
#include "memory/particle_store.h"
#include "parallel/random_stream.h"

namespace fastslam::engine::internal {

// The motion stage's per-thread buffers.
struct MotionScratch {
  std::vector<double> columns;
  std::vector<double> weights;  // the block's lanes' weights while recording the trajectory
  std::vector<ControlStep> steps;
  std::vector<std::uint64_t> keys;
};

// What the motion stage reads besides the particles.
struct MotionInput {
  std::span<const PendingControl> pending;
  std::uint64_t seed = 0;
  // The set's index of local particle 0 (a rank's share of a distributed set; 0 otherwise):
  // the streams are keyed by the set's indices.
  std::uint32_t first_particle = 0;
  double sigma_control[2] = {0.0, 0.0};
  const MotionNormalsWindow* ahead = nullptr;  // FastSLAM 1.0: normals drawn ahead (may be empty)
  // The composed motion's runs of `pending` and each control's mean displacement from its run's
  // start (engine/motion_run.h); empty under the draw per control.
  std::span<const MotionRun> runs;
  std::span<const Eigen::Vector3d> partial;
};

// Whether a model can take the composed motion (engine/motion_run.h).
template <class Motion>
inline constexpr bool kComposable = Motion::kStateDim == 3 && !Motion::kNoOdometry;

namespace motion_pass_detail {

// Batches of at most kStepBatch controls bound the scratch when many controls are queued.
inline constexpr std::size_t kStepBatch = 64;

// FastSLAM 1.0: the two motion normals of every lane and step of one batch, stream (seed, step,
// particle, kMotion), step j's pair in normals[2 j lanes, ...). Drawn for the padding lanes too
// (the streams of the particles after the block; their values go nowhere): whole vectors.
inline void draw_motion_normals(const MotionInput& in, std::span<const std::uint64_t> keys,
                                std::size_t begin, std::size_t lanes, std::span<double> normals) {
  const std::size_t drawn = in.ahead->copy(keys, begin, lanes, normals);
  if (drawn < keys.size()) {
    const std::span<double> rest = normals.subspan(2 * drawn * lanes);
    parallel::normal_pairs_for_particles(in.seed, keys.subspan(drawn), parallel::Purpose::kMotion,
                                         in.first_particle + static_cast<std::uint32_t>(begin),
                                         lanes, rest,
                                         rest.subspan(lanes), 2 * lanes);
  }
}

// The composed motion on lanes [0, lanes) of (x, y, theta), lane l being particle begin + l:
// FastSLAM 1.0 draws each run (three normals per lane), 2.0 (`cov`, the six upper-triangle
// columns; null for 1.0) carries its mean and covariance through it.
inline void advance_composed(const MotionInput& in, std::size_t begin, std::size_t lanes, double* x,
                             double* y, double* theta, double* const* cov,
                             const TrajectorySums* record, const double* w,
                             MotionScratch& scratch) {
  // FastSLAM 1.0's normals: the four columns after the states.
  double* const n0 = scratch.columns.data() + 3 * lanes;
  double* const n1 = n0 + lanes;
  double* const n2 = n1 + lanes;
  double* const spare = n2 + lanes;
  const auto first = in.first_particle + static_cast<std::uint32_t>(begin);
  for (const MotionRun& run : in.runs) {
    const std::size_t last = run.first + run.count - 1;
    // The points inside a run come from its start's sums (TrajectoryRecorder::finish): the
    // pass's start for the first run, the previous run's end for the others.
    if (record != nullptr && run.count > 1 && run.first == 0) {
      record->add_start(begin, lanes, x, y, theta, w);
    }
    if (cov != nullptr) {
      predict_run_covariance(run, lanes, theta, cov);
      apply_run_mean(run, lanes, x, y, theta);
    } else {
      const std::uint64_t key = in.pending[last].step;
      parallel::normal_pairs_for_particles(in.seed, key, parallel::Purpose::kMotionRun, first,
                                           lanes, std::span(n0, lanes), std::span(n1, lanes));
      parallel::normal_pairs_for_particles(in.seed, key, parallel::Purpose::kMotionRunHeading,
                                           first, lanes, std::span(n2, lanes),
                                           std::span(spare, lanes));
      apply_run(run, lanes, x, y, theta, n0, n1, n2);
    }
    if (record != nullptr) record->add(last, begin, lanes, x, y, theta, w);
  }
}

}  // namespace motion_pass_detail

// Applies in.pending to particles [begin, begin + count) of `store` (and, for 2.0, their
// covariances). `record` is null unless the trajectory is recorded.
template <class Motion, bool kFs2>
void advance_block(const Motion& motion, const MotionInput& in, memory::ParticleStore& store,
                   PoseCovariances& covariances, std::size_t begin, std::size_t count,
                   const TrajectorySums* record, MotionScratch& scratch) {
  using motion_pass_detail::kStepBatch;
  constexpr int N = Motion::kStateDim;
  constexpr int E = kCovEntries<N>;
  const typename Motion::Control sigmas(in.sigma_control[0], in.sigma_control[1]);
  const std::size_t lanes = padded_lanes(count);
  const std::size_t k_steps = in.pending.size();
  bool composed = false;
  if constexpr (kComposable<Motion>) composed = !in.runs.empty();
  // Columns: N states, then (2.0) E covariance entries, (1.0) two normals per step of a batch,
  // or (1.0 composed) four normal columns.
  const std::size_t columns =
      N + (kFs2 ? E : (composed ? 4 : 2 * std::min(k_steps, kStepBatch)));
  scratch.columns.resize(columns * lanes);
  auto column = [&](std::size_t c) { return scratch.columns.data() + c * lanes; };
  scratch.steps.resize(k_steps);
  scratch.keys.resize(k_steps);
  for (std::size_t k = 0; k < k_steps; ++k) {
    const PendingControl& c = in.pending[k];
    scratch.steps[k] = {c.u0, c.u1, c.dt};
    if constexpr (Motion::kNoOdometry) scratch.steps[k].u0 = scratch.steps[k].u1 = 0;
    scratch.keys[k] = c.step;
  }
  double* const store_col[5] = {store.x().data(), store.y().data(), store.theta().data(),
                                store.v().data(), store.omega().data()};
  StateBlock<N> block;
  block.lanes = lanes;
  for (int k = 0; k < N; ++k) {
    block.col[k] = column(k);
    std::copy_n(store_col[k] + begin, count, block.col[k]);
    std::fill(block.col[k] + count, block.col[k] + lanes, 0.0);  // padding lanes: any finite
  }
  CovBlock<N> cov{};
  if constexpr (kFs2) {
    for (int e = 0; e < E; ++e) cov[e] = column(N + e);
    covariances.load_upper<N>(begin, count, cov.data());
    for (int e = 0; e < E; ++e) std::fill(cov[e] + count, cov[e] + lanes, 0.0);
  }
  if (record != nullptr) {
    scratch.weights.resize(lanes);
    record->weights(begin, lanes, scratch.weights.data());
  }
  if constexpr (kComposable<Motion>) {
    if (composed) {
      motion_pass_detail::advance_composed(in, begin, lanes, block.col[0], block.col[1],
                                           block.col[2], kFs2 ? cov.data() : nullptr, record,
                                           scratch.weights.data(), scratch);
      for (int k = 0; k < N; ++k) std::copy_n(block.col[k], count, store_col[k] + begin);
      if constexpr (kFs2) covariances.store_upper<N>(begin, count, cov.data());
      return;
    }
  }
  // Recording the trajectory needs the poses after every step; otherwise one call runs a batch.
  const std::size_t per_call = record != nullptr ? 1 : kStepBatch;
  for (std::size_t first = 0; first < k_steps; first += kStepBatch) {
    const std::size_t batch = std::min(kStepBatch, k_steps - first);
    if constexpr (!kFs2) {
      motion_pass_detail::draw_motion_normals(in, std::span(scratch.keys).subspan(first, batch),
                                              begin, lanes,
                                              std::span(column(N), 2 * batch * lanes));
    }
    for (std::size_t j = 0; j < batch; j += per_call) {
      const std::size_t k = first + j;
      const std::span<const ControlStep> run(scratch.steps.data() + k,
                                             std::min(per_call, batch - j));
      if constexpr (kFs2) {
        predict_block(motion, block, run, sigmas, cov);
      } else {
        sample_block(motion, block, run, sigmas, column(N + 2 * j));
      }
      if (record != nullptr) {
        record->add(k, begin, lanes, block.col[0], block.col[1], block.col[2],
                    scratch.weights.data());
      }
    }
  }
  for (int k = 0; k < N; ++k) std::copy_n(block.col[k], count, store_col[k] + begin);
  if constexpr (kFs2) covariances.store_upper<N>(begin, count, cov.data());
}

}  // namespace fastslam::engine::internal
