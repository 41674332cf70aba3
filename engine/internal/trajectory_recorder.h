// Trajectory recording (FilterConfig::record_trajectory): the weighted-mean pose after every
// control. A pass that runs queued controls first `begin`s (the largest log-weight of the set,
// since the controls do not change the weights), then the motion stage adds, after every
// control, the weighted sums of each group of kMotionLanes lanes (TrajectorySums::add: w, w x,
// w y, w cos, w sin, each group summed in one fixed order), and `finish` folds the groups in
// order, control by control. Pass blocks hold whole groups, so the points are bit-identical for
// any block split and thread count; a rank of a shared particle set (parallel/collective.h)
// holds whole groups too, takes the set's largest log-weight and folds every rank's groups in
// rank order, so every rank records the points one process would. Owns the group sums and the
// points not yet taken; borrows the group.
// Under the composed motion draw the motion stage adds the sums only at each run's start and
// end; `finish` folds a run's start once and moves the total by the run's mean displacement
// for each control inside it (every lane moves by the same displacement, so the sums move as
// one): O(1) per control.
// Thread safety: thread-compatible; the motion stage adds disjoint groups concurrently. Costs:
// per added control and lane a sincos and five multiply-adds in the motion stage; finish
// O(M S / 8 + K) for K controls of which S were added; the sums (5 M (K + 1) / 8 doubles) are
// reused.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "engine/filter.h"
#include "engine/motion_run.h"
#include "parallel/collective.h"

namespace fastslam::engine::internal {

// The motion stage's view of a recording pass. Lane group g is local particles
// [8 g, 8 g + 8); a group past the last particle's is padding with weight 0.
struct TrajectorySums {
  static constexpr std::size_t kTerms = 5;  // w, w x, w y, w cos(theta), w sin(theta)
  static constexpr std::size_t kGroup = 8;  // kMotionLanes (engine/motion_batch.h)

  std::span<const double> log_weight;  // the local particles'
  double shift = 0.0;                  // the set's largest log-weight: w = exp(l - shift)
  std::size_t groups = 0;              // lane groups of the local particles
  // Every local log-weight equals `shift` (as after a resampling): every w is exp(0) = 1.
  bool uniform = false;
  // Slot s, group g, term t at [(s groups + g) kTerms + t]: slot 0 holds the pass's start
  // (add_start), slot k + 1 the poses after control k (add).
  double* sums = nullptr;

  // The weights of lanes [begin, begin + lanes) to w (0 past the last particle).
  // REQUIRES: begin % kGroup == 0, lanes % kGroup == 0.
  void weights(std::size_t begin, std::size_t lanes, double* w) const;
  // The sums of the groups of lanes [begin, begin + lanes) after control k, from the lanes'
  // x, y, theta (|theta| <= parallel::kSinCosMaxArg) and weights w (all lane-indexed from 0).
  // REQUIRES: as weights().
  void add(std::size_t k, std::size_t begin, std::size_t lanes, const double* x, const double* y,
           const double* theta, const double* w) const;
  // The same at the pass's start, before its first control: the composed motion draw's first
  // run reads it (TrajectoryRecorder::finish).
  void add_start(std::size_t begin, std::size_t lanes, const double* x, const double* y,
                 const double* theta, const double* w) const;
  // The groups' sums of lanes [0, lanes) into out (kTerms per group), as add() computes them.
  static void group_sums(std::size_t lanes, const double* x, const double* y, const double* theta,
                         const double* w, double* out);
};

class TrajectoryRecorder {
 public:
  // `group`: the ranks sharing the particle set (nullptr: this process holds all of it).
  explicit TrajectoryRecorder(parallel::Collective* group = nullptr) : group_(group) {}

  // Prepares for `controls` controls over the local particles with log-weights `log_weight`
  // (read by the motion stage: unchanged until each block's motion is done).
  void begin(std::span<const double> log_weight, std::size_t controls);
  // Where the motion stage adds its groups' sums (valid until the next begin).
  const TrajectorySums& sums() const { return view_; }
  // Appends one point per control; the first is control number `first_control`. `runs` and
  // `partial`: the composed motion draw's runs of the pass and each control's mean displacement
  // from its run's start (engine/motion_run.h), when the motion stage added the sums only at
  // the runs' starts and ends; empty when it added them after every control.
  void finish(std::size_t controls, std::uint64_t first_control,
              std::span<const MotionRun> runs = {}, std::span<const Eigen::Vector3d> partial = {});

  // The points recorded and not taken yet (saved with the state).
  std::vector<TrajectoryPoint>& points() { return points_; }
  const std::vector<TrajectoryPoint>& points() const { return points_; }

 private:
  parallel::Collective* group_;
  std::vector<double> sums_;
  TrajectorySums view_;
  std::vector<TrajectoryPoint> points_;
};

}  // namespace fastslam::engine::internal
