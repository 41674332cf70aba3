// Per-scan latency of a run (metrics.json's "scan_latency_ms"): the time each scan's update
// took, kept as a histogram of logarithmic buckets so that a run of 10^7 scans costs the same
// few kilobytes as one of ten. A percentile is the upper edge of the bucket holding that rank,
// so it is at most kRelativeWidth above the exact order statistic and never below it; the
// minimum, the maximum and the mean are exact.
//
// Ownership: owns its buckets. Thread safety: thread-compatible. Costs: add is O(1) (a log2 and
// an increment); percentile is O(buckets); about 2,800 buckets of 8 bytes.
#pragma once

#include <cstdint>
#include <vector>

namespace fastslam::tools {

class LatencyHistogram {
 public:
  // Buckets grow by this factor: a reported percentile is within 1% of the exact one.
  static constexpr double kRelativeWidth = 0.01;
  // Latencies up to kFloorSeconds share the first bucket (reported as at most the floor), above
  // kCeilingSeconds the last (reported as the maximum).
  static constexpr double kFloorSeconds = 1e-8;
  static constexpr double kCeilingSeconds = 1e4;

  LatencyHistogram();

  // Records one latency (negative or NaN counts as zero).
  void add(double seconds);

  std::uint64_t count() const { return count_; }
  double min() const { return count_ ? min_ : 0.0; }
  double max() const { return count_ ? max_ : 0.0; }
  double mean() const { return count_ ? sum_ / static_cast<double>(count_) : 0.0; }
  // The q-quantile (0 < q <= 1) by the nearest-rank rule: the latency of rank ceil(q n), given
  // as the upper edge of its bucket, clamped to [min, max]. 0 when empty.
  double percentile(double q) const;

 private:
  std::vector<std::uint64_t> buckets_;
  std::uint64_t count_ = 0;
  double sum_ = 0.0;
  double min_ = 0.0, max_ = 0.0;
};

}  // namespace fastslam::tools
