// The largest and smallest of a particle set's log-weights, as the plain ordered scans give them,
// in four-lane selects: the scans chase a dependency through each comparison (about 2.5 ns a
// particle, on the calling thread of every scan), the selects vectorise. Used by the
// trajectory's weights and the most likely particle.
// Thread safety: pure functions. Costs: O(M), no allocation.
#pragma once

#include <cstddef>
#include <cstring>
#include <span>

namespace fastslam::engine::internal {

struct SelectRange {
  double low = 0.0;   // from v[0], replaced by each later v < it
  double high = 0.0;  // from v[0], replaced by each later v > it
  bool nan = false;   // whether any v is a NaN
};

// REQUIRES: !v.empty(). Without a NaN, `low` and `high` are the smallest and largest value
// (equal ones in any order: they differ at most in the sign of a zero). A NaN never replaces
// a value; a NaN v[0] is never replaced.
inline SelectRange select_range(std::span<const double> v) noexcept {
  using Four = double __attribute__((vector_size(32)));  // GCC does not vectorise these alone
  Four low4 = {v[0], v[0], v[0], v[0]};
  Four high4 = low4;
  Four nan4 = {};
  std::size_t i = 0;
  for (; i + 4 <= v.size(); i += 4) {
    Four x;
    std::memcpy(&x, v.data() + i, sizeof(Four));
    low4 = x < low4 ? x : low4;
    high4 = x > high4 ? x : high4;
    nan4 = x != x ? x : nan4;
  }
  SelectRange r{low4[0], high4[0],
                nan4[0] != 0.0 || nan4[1] != 0.0 || nan4[2] != 0.0 || nan4[3] != 0.0};
  for (int k = 1; k < 4; ++k) {
    r.low = low4[k] < r.low ? low4[k] : r.low;
    r.high = high4[k] > r.high ? high4[k] : r.high;
  }
  for (; i < v.size(); ++i) {
    r.low = v[i] < r.low ? v[i] : r.low;
    r.high = v[i] > r.high ? v[i] : r.high;
    r.nan = r.nan || v[i] != v[i];
  }
  return r;
}

// The index `for (i...) if (v[i] > v[best]) best = i;` ends with from best = 0: the first of
// the largest values (NaNs never win; 0 when v[0] is a NaN). REQUIRES: !v.empty().
inline std::size_t first_largest(std::span<const double> v) noexcept {
  const double high = select_range(v).high;
  if (high != high) return 0;
  std::size_t i = 0;
  while (!(v[i] == high)) ++i;
  return i;
}

}  // namespace fastslam::engine::internal
