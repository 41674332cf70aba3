// Innovation consistency of a run, metrics.json's "innovations": the squared Mahalanobis
// distances (NIS) of the associations the filter reports after every scan (the most likely
// particle's, engine::Estimate::associations), against the chi-square law with two degrees of
// freedom that they follow when the filter's noise model is the data's. Needs no ground truth,
// so it tells a user of real data whether the noises fit: counted are the fractions beyond the
// law's 50 %, 95 % and 99 % points (0.5, 0.05 and 0.01 for a consistent model) and the mean
// (2). A particle filter's report is its most likely particle's, which the weights picked for
// small distances: on data drawn from the model about 0.3 rather than 0.5 lie beyond the median
// (the webmap, FastSLAM 1.0), while the EKF's follow the law. Under unknown association the
// distances are those of the chosen landmarks, cut off by the gate and by ln p0. Both make the
// test understate a misfit, never invent one.
//
// Ownership: plain counts. Thread safety: thread-compatible. Costs: add is O(observations of
// the scan); the state is a few counters, saved whole in a checkpoint.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>

#include <nlohmann/json_fwd.hpp>

#include "engine/filter.h"

namespace fastslam::tools {

class InnovationStats {
 public:
  // The chi-square (2 degrees of freedom) upper-tail points: P(NIS > bound) = tail, bound =
  // -2 ln tail.
  struct Point {
    double tail;
    double bound;
  };
  static constexpr std::array<Point, 3> kPoints = {
      {{0.5, 1.3862943611198906}, {0.05, 5.9914645471079799}, {0.01, 9.2103403719761836}}};

  // Counts one scan's report: associated observations by their distance (a non-finite one
  // counts beyond every point and not in the mean), new and discarded ones by number.
  void add(std::span<const engine::ObservationAssociation> scan) noexcept;

  std::uint64_t associated() const noexcept { return associated_; }
  std::uint64_t started() const noexcept { return started_; }
  std::uint64_t discarded() const noexcept { return discarded_; }
  // Mean NIS over the finite distances; NaN when there are none.
  double mean() const noexcept;
  // Fraction of the associated observations beyond kPoints[k]; NaN when there are none.
  double beyond(std::size_t k) const noexcept;

  // When there are enough associations (kMinimum) and the fraction beyond the 99 % point is at
  // least kWide times the law's, the sentence that says so and what to do; else nothing.
  static constexpr std::uint64_t kMinimum = 100;
  static constexpr double kWide = 5.0;
  std::optional<std::string> warning() const;

  // What was counted after `earlier` (an earlier copy of this one): the counts' differences
  // and the difference of the running sums. REQUIRES: `earlier` is such a copy.
  InnovationStats since(const InnovationStats& earlier) const noexcept;

  // metrics.json's object, and the checkpoint's state (exact: counts and the sum's bits).
  nlohmann::json metrics() const;
  nlohmann::json state() const;
  // Throws nlohmann::json::exception for a state of the wrong shape.
  static InnovationStats from_state(const nlohmann::json& j);

 private:
  std::uint64_t associated_ = 0;
  std::uint64_t finite_ = 0;
  std::uint64_t started_ = 0;
  std::uint64_t discarded_ = 0;
  std::array<std::uint64_t, kPoints.size()> beyond_ = {};
  double sum_ = 0.0;
};

}  // namespace fastslam::tools
