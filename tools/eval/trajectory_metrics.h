// Streaming trajectory metrics in evo's definitions (github.com/MichaelGrupp/evo): the raw
// position error (ATE), the ATE after the rigid SE(2) alignment (Horn/Umeyama, no scale, as
// `evo_ape --align`) and the relative pose error over a travelled distance (as `evo_rpe
// --delta D --delta_unit m`), for runs too long to hold their trajectory. Estimates and
// references are fed in time order, each stream on its own; a reference is paired with the
// estimate at its stamp by pose_at's rule (trajectory_errors.h) once the estimates around it
// have arrived, so the results equal the batch functions on the whole streams. Definitions and
// pairing rules: docs/evaluation.md.
//
// Ownership: a value type; copies every sample it keeps. Thread safety: thread-compatible (const
// methods may run concurrently, the rest exclusive). Costs: add_estimate and add_reference
// O(1) amortised; memory O(pending references + estimate samples newer than the later of the
// next reference's time and the newest estimate's time - max_reference_delay): the gap between
// the filter's batches, never the whole trajectory. finish() O(pending x log(buffered)), no
// allocation.
#pragma once

#include <cstddef>
#include <deque>
#include <limits>
#include <optional>
#include <vector>

#include "tools/eval/trajectory_errors.h"
#include "tools/io/tum.h"

namespace fastslam::tools {

struct TrajectoryEvaluatorOptions {
  // Truth poses carry a heading; GPS fixes do not (their theta is ignored, and the RPE has no
  // rotation part).
  bool reference_heading = true;
  // m of reference path between the two poses of an RPE pair; > 0 (1 indoors, 10 outdoors).
  double rpe_delta = 10.0;
  // s: how far a reference may trail the estimates already added. Estimate samples older than
  // that are dropped; a reference that would need one throws (see add_reference).
  double max_reference_delay = kMaxInterpolationGap;
};

// ATE after the least-squares rigid motion of the estimate onto the reference.
struct AlignedAte {
  double rmse = 0.0;        // m
  double rotation = 0.0;    // rad; aligned estimate = R(rotation) p + (x, y)
  double x = 0.0, y = 0.0;  // m
};

struct RelativePoseErrors {
  double delta = 0.0;  // m of reference path per pair
  std::size_t pairs = 0;
  double translation_rmse = 0.0;  // m
  // rad, the angle of the relative rotation error; only for references with a heading.
  std::optional<double> rotation_rmse;
};

struct TrajectoryMetrics {
  PositionErrors raw;                    // equal to position_errors() on the whole streams
  double raw_mean = 0.0, raw_max = 0.0;  // m
  AlignedAte aligned;
  RelativePoseErrors rpe;
};

class TrajectoryEvaluator {
 public:
  // Throws std::invalid_argument unless rpe_delta is finite and > 0 and max_reference_delay
  // >= 0 (infinity: keep every estimate sample).
  explicit TrajectoryEvaluator(const TrajectoryEvaluatorOptions& options);

  // REQUIRES: finite values; time not before the previous estimate's (equal stamps: the last
  // one counts, as in pose_at). Throws std::invalid_argument otherwise. Pairs the pending
  // references it completes.
  void add_estimate(const StampedPose& estimate);
  // REQUIRES: finite x, y, time (and theta with reference_heading); time not before the
  // previous reference's. Throws std::invalid_argument otherwise, and std::logic_error when
  // the estimate samples around its time were already dropped (it trails the newest estimate
  // by more than max_reference_delay).
  void add_reference(const StampedPose& reference);

  // The metrics as if both streams ended now: pending references are paired with the samples
  // held (an exact stamp, else skipped, as pose_at does at the end of the estimate). The
  // evaluator may be fed further afterwards.
  TrajectoryMetrics finish() const;

  // Estimate samples and references held, for tests of the memory bound.
  std::size_t buffered_estimates() const { return estimates_.size() - head_; }
  std::size_t pending_references() const { return pending_.size(); }

 private:
  // Running sums: all O(1), centred (Welford) where they feed a difference of large terms.
  struct Sums {
    PositionErrors raw;
    double raw_se = 0.0, raw_sum = 0.0, raw_max = 0.0;
    // Alignment: a = estimate position, d = reference - estimate; means and co-moments.
    double mean_a[2] = {0, 0}, mean_d[2] = {0, 0};
    double aa = 0.0, dd = 0.0, ad_dot = 0.0, ad_cross = 0.0;
    // RPE: the reference path since the last anchor, and the anchor pair.
    bool started = false;
    double path = 0.0, previous[2] = {0, 0};
    std::optional<StampedPose> anchor_estimate, anchor_reference;
    std::size_t pairs = 0;
    double rot_se = 0.0;
    // Per pair: with headings, the squared translation error; without, the sums that give
    // |R dp - dq|^2 for the final alignment R (dp, dq the displacements, u = dq - dp).
    double trans_se = 0.0, pp = 0.0, uu = 0.0, pu_dot = 0.0, pu_cross = 0.0;

    void add(const StampedPose& estimate, const StampedPose& reference,
             const TrajectoryEvaluatorOptions& options);
  };

  void resolve(const StampedPose& reference, Sums& sums) const;
  void prune();

  TrajectoryEvaluatorOptions options_;
  // Estimate samples from head_ on; a vector (not a deque) so pose_at gets a span.
  std::vector<StampedPose> estimates_;
  std::size_t head_ = 0;
  bool dropped_ = false;
  std::deque<StampedPose> pending_;  // references newer than every estimate, in time order
  double last_reference_ = -std::numeric_limits<double>::infinity();
  Sums sums_;
};

}  // namespace fastslam::tools
