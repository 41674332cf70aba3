#include "tools/eval/latency_histogram.h"

#include <algorithm>
#include <cmath>

namespace fastslam::tools {
namespace {

const double kLogBase = std::log(1.0 + LatencyHistogram::kRelativeWidth);
const double kLogFloor = std::log(LatencyHistogram::kFloorSeconds);

std::size_t bucket_count() {
  return static_cast<std::size_t>(
             std::ceil((std::log(LatencyHistogram::kCeilingSeconds) - kLogFloor) / kLogBase)) +
         1;
}

// Bucket b holds latencies in (floor (1+w)^(b-1), floor (1+w)^b]; bucket 0 everything up to the
// floor.
std::size_t bucket_of(double seconds, std::size_t buckets) {
  if (!(seconds > LatencyHistogram::kFloorSeconds)) return 0;
  const double b = std::ceil((std::log(seconds) - kLogFloor) / kLogBase);
  return std::min(buckets - 1, static_cast<std::size_t>(std::max(1.0, b)));
}

double upper_edge(std::size_t b) { return std::exp(kLogFloor + static_cast<double>(b) * kLogBase); }

}  // namespace

LatencyHistogram::LatencyHistogram() : buckets_(bucket_count(), 0) {}

void LatencyHistogram::add(double seconds) {
  if (!(seconds > 0.0)) seconds = 0.0;
  ++buckets_[bucket_of(seconds, buckets_.size())];
  min_ = count_ == 0 ? seconds : std::min(min_, seconds);
  max_ = count_ == 0 ? seconds : std::max(max_, seconds);
  sum_ += seconds;
  ++count_;
}

double LatencyHistogram::percentile(double q) const {
  if (count_ == 0) return 0.0;
  q = std::clamp(q, 0.0, 1.0);
  const auto rank = std::max<std::uint64_t>(
      1, static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(count_))));
  std::uint64_t seen = 0;
  for (std::size_t b = 0; b < buckets_.size(); ++b) {
    seen += buckets_[b];
    if (seen >= rank) {
      return b + 1 == buckets_.size() ? max_ : std::clamp(upper_edge(b), min_, max_);
    }
  }
  return max_;
}

}  // namespace fastslam::tools
