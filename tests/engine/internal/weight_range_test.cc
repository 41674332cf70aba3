// The four-lane log-weight scans against the plain ordered loops they replace: every length 1-40
// (the lanes and the tail), the extremes anywhere, ties, signed zeros, infinities and NaNs.
#include "engine/internal/weight_range.h"

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::engine::internal {
namespace {

std::vector<std::vector<double>> cases() {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  std::mt19937_64 rng(9);
  std::vector<std::vector<double>> out;
  for (std::size_t m = 1; m <= 40; ++m) {
    for (int trial = 0; trial < 300; ++trial) {
      std::vector<double> v(m);
      const int kind = trial % 6;
      for (double& x : v) {
        // Few distinct values, so that ties are common; kind 1 mixes the two zeros.
        x = kind == 1 ? (rng() % 2 == 0 ? 0.0 : -0.0) - static_cast<double>(rng() % 3)
                      : -static_cast<double>(rng() % 7) / 4.0;
      }
      if (kind == 2) v[rng() % m] = -inf;
      if (kind == 3) v[rng() % m] = inf;
      if (kind == 4) v[rng() % m] = nan;
      if (kind == 5) v[0] = nan;
      out.push_back(v);
    }
  }
  return out;
}

TEST(WeightRange, SelectRangeIsTheOrderedScan) {
  for (const std::vector<double>& v : cases()) {
    double low = v[0];
    double high = v[0];
    bool nan = false;
    for (const double x : v) {
      if (x < low) low = x;
      if (x > high) high = x;
      nan = nan || std::isnan(x);
    }
    const SelectRange r = select_range(v);
    ASSERT_EQ(r.nan, nan);
    if (std::isnan(v[0])) {
      EXPECT_TRUE(std::isnan(r.low) && std::isnan(r.high));
    } else {
      // Equal values may come from either zero; the value itself is the scan's.
      EXPECT_EQ(r.low, low);
      EXPECT_EQ(r.high, high);
    }
  }
}

TEST(WeightRange, FirstLargestIsTheScalarArgmax) {
  for (const std::vector<double>& v : cases()) {
    std::size_t best = 0;
    for (std::size_t i = 1; i < v.size(); ++i) {
      if (v[i] > v[best]) best = i;
    }
    EXPECT_EQ(first_largest(v), best);
  }
}

}  // namespace
}  // namespace fastslam::engine::internal
