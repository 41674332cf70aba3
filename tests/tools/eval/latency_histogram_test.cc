#include "tools/eval/latency_histogram.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::tools {
namespace {

// The nearest-rank percentile of a sorted sample: the oracle.
double exact(const std::vector<double>& sorted, double q) {
  const auto rank = std::max<std::size_t>(
      1, static_cast<std::size_t>(std::ceil(q * static_cast<double>(sorted.size()))));
  return sorted[rank - 1];
}

TEST(LatencyHistogram, PercentilesAreWithinOneBucketAboveTheExactOrderStatistic) {
  std::mt19937_64 random(3);
  // Log-normal latencies around 50 us with a heavy tail, and a few outliers of seconds.
  std::lognormal_distribution<double> latency(std::log(50e-6), 1.2);
  for (const std::size_t n : {1u, 2u, 7u, 100u, 10007u}) {
    LatencyHistogram h;
    std::vector<double> sample;
    for (std::size_t i = 0; i < n; ++i) {
      const double s = i % 997 == 5 ? 2.5 : latency(random);
      h.add(s);
      sample.push_back(s);
    }
    std::sort(sample.begin(), sample.end());
    ASSERT_EQ(h.count(), n);
    EXPECT_EQ(h.min(), sample.front());
    EXPECT_EQ(h.max(), sample.back());
    double sum = 0.0;
    for (double s : sample) sum += s;
    EXPECT_NEAR(h.mean(), sum / static_cast<double>(n), 1e-12 * sum);
    for (const double q : {0.01, 0.5, 0.9, 0.99, 0.999, 1.0}) {
      const double want = exact(sample, q);
      const double got = h.percentile(q);
      EXPECT_GE(got, want) << "n " << n << " q " << q;
      EXPECT_LE(got, want * (1.0 + LatencyHistogram::kRelativeWidth) * (1.0 + 1e-12))
          << "n " << n << " q " << q;
    }
  }
}

TEST(LatencyHistogram, EmptyZeroNegativeAndOutOfRangeLatencies) {
  LatencyHistogram h;
  EXPECT_EQ(h.percentile(0.5), 0.0);
  EXPECT_EQ(h.max(), 0.0);
  h.add(-1.0);
  h.add(std::nan(""));
  h.add(0.0);
  EXPECT_EQ(h.count(), 3u);
  EXPECT_EQ(h.max(), 0.0);
  EXPECT_EQ(h.percentile(1.0), 0.0);
  h.add(1e6);  // beyond the last bucket: the maximum is still exact
  EXPECT_EQ(h.max(), 1e6);
  EXPECT_EQ(h.percentile(1.0), 1e6);
  EXPECT_LE(h.percentile(0.5), LatencyHistogram::kFloorSeconds);
}

}  // namespace
}  // namespace fastslam::tools
