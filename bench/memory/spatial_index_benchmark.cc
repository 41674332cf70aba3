// Benchmarks of the spatial index (docs/spatial-index.md has the results and commands). Maps
// hold N points uniform in a square of side sqrt(N) * 10 m (constant density: one landmark per
// 100 m^2), so a query of radius 30 m (a sensor range) returns about 28 entries at every N and
// the time per query should be nearly flat in N.
//
//   BM_SpatialIndexWithin<Policy>/N            one within() query, radius 30 m, ns per query;
//                                               counter results = entries per query.
//   BM_SpatialIndexFootprint/N                 in_footprint(), 30 m, 180 degrees.
//   BM_SpatialIndexNearest/N                   nearest(), k = 8.
//   BM_SpatialIndexMove<Policy>/N/shared/dist  move a random entry by `dist` cm (5: an EKF
//       update, stays in its leaf; 500: a loop closure, leaves it). shared = 1: on a fresh copy
//       of the base (path copying, then the copy is released: the cost per landmark after
//       resampling); shared = 0: in place on the base, moved back the next time.
//   BM_SpatialIndexInsert<Policy>/N/shared     shared = 0: insert a point into the base and
//       erase it again (ns per pair, in place); shared = 1: copy, insert, release.
//   BM_BruteForceWithin/N                      the same query as a scan of a vector.
// The shape comparison is BM_SpatialIndexWithin / Move / Insert over several SpatialPolicy
// shapes. Sizes follow fastslam::bench::upto (FASTSLAM_BENCH_SMOKE=1: tiny sizes).
#include <cmath>
#include <cstdint>
#include <map>
#include <memory>
#include <random>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench/bench_util.h"
#include "memory/node_heap.h"
#include "memory/spatial_index.h"

namespace fastslam::memory {
namespace {

using bench::upto;

using Q1B8 = SpatialPolicy<1, 8, AtomicRefcount>;
using Q1B16 = DefaultSpatialPolicy;
using Q2B8 = SpatialPolicy<2, 8, AtomicRefcount>;
using Q2B16 = SpatialPolicy<2, 16, AtomicRefcount>;

constexpr double kRange = 30.0;

double side_of(std::int64_t n) { return std::sqrt(static_cast<double>(n)) * 10.0; }

// The points of the map of size n (deterministic).
const std::vector<SpatialEntry>& points(std::int64_t n) {
  static std::map<std::int64_t, std::vector<SpatialEntry>> cache;
  std::vector<SpatialEntry>& p = cache[n];
  if (p.empty()) {
    std::mt19937_64 rng(static_cast<std::uint64_t>(n));
    std::uniform_real_distribution<double> u(0.0, side_of(n));
    p.resize(static_cast<std::size_t>(n));
    for (std::int64_t i = 0; i < n; ++i) {
      p[static_cast<std::size_t>(i)] = {static_cast<Slot>(i), 0.0f, u(rng), u(rng)};
    }
  }
  return p;
}

// Base indexes, built once per (policy, n) and kept for the run; held by one handle.
template <class Policy>
class Bases {
 public:
  using Index = BasicSpatialIndex<Policy>;
  static PoolHeap& heap() {
    static PoolHeap heap;
    return heap;
  }
  static Index& get(std::int64_t n) {
    PoolHeap& h = heap();  // constructed before (destroyed after) the cache
    static std::map<std::int64_t, std::unique_ptr<Index>> cache;
    std::unique_ptr<Index>& index = cache[n];
    if (!index) {
      index = std::make_unique<Index>(h);
      for (const SpatialEntry& e : points(n)) {
        index->insert(e.slot, e.x, e.y);
      }
    }
    return *index;
  }
};

// Random query points in the square, precomputed.
class PointStream {
 public:
  PointStream(double side, std::uint64_t seed) : xy_(2 * kCount) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(0.0, side);
    for (double& v : xy_) {
      v = u(rng);
    }
  }
  std::pair<double, double> next() noexcept {
    const std::size_t i = next_++ & (kCount - 1);
    return {xy_[2 * i], xy_[2 * i + 1]};
  }

 private:
  static constexpr std::size_t kCount = 1 << 14;
  std::vector<double> xy_;
  std::size_t next_ = 0;
};

template <class Policy>
void BM_SpatialIndexWithin(benchmark::State& state) {
  const std::int64_t n = state.range(0);
  const auto& index = Bases<Policy>::get(n);
  PointStream queries(side_of(n), 2);
  std::int64_t found = 0;
  for (auto _ : state) {
    const auto [x, y] = queries.next();
    index.within(x, y, kRange, [&](const SpatialEntry& e) {
      ++found;
      benchmark::DoNotOptimize(&e);
    });
  }
  state.counters["results"] =
      static_cast<double>(found) / static_cast<double>(state.iterations());
}

void BM_SpatialIndexFootprint(benchmark::State& state) {
  const std::int64_t n = state.range(0);
  const auto& index = Bases<Q1B16>::get(n);
  PointStream queries(side_of(n), 3);
  std::int64_t found = 0;
  double heading = 0.0;
  for (auto _ : state) {
    const auto [x, y] = queries.next();
    heading += 0.7;
    index.in_footprint(x, y, heading, kRange, 3.14159, [&](const SpatialEntry& e) {
      ++found;
      benchmark::DoNotOptimize(&e);
    });
  }
  state.counters["results"] =
      static_cast<double>(found) / static_cast<double>(state.iterations());
}

void BM_SpatialIndexNearest(benchmark::State& state) {
  const std::int64_t n = state.range(0);
  const auto& index = Bases<Q1B16>::get(n);
  PointStream queries(side_of(n), 4);
  std::vector<SpatialEntry> out(8);
  for (auto _ : state) {
    const auto [x, y] = queries.next();
    benchmark::DoNotOptimize(index.nearest(x, y, 8, out));
  }
}

template <class Policy>
void BM_SpatialIndexMove(benchmark::State& state) {
  using Index = BasicSpatialIndex<Policy>;
  const std::int64_t n = state.range(0);
  const bool shared = state.range(1) != 0;
  const double dist = static_cast<double>(state.range(2)) * 0.01;
  Index& base = Bases<Policy>::get(n);
  std::vector<SpatialEntry> pos = points(n);  // where the base holds each entry
  std::mt19937_64 rng(5);
  std::vector<std::uint32_t> picks(1 << 14);
  for (auto& p : picks) {
    p = static_cast<std::uint32_t>(rng() % static_cast<std::uint64_t>(n));
  }
  const double side = side_of(n);
  std::size_t next = 0;
  if (shared) {
    for (auto _ : state) {
      const SpatialEntry& e = pos[picks[next++ & (picks.size() - 1)]];
      Index copy = base;
      copy.move(e.slot, e.x, e.y, std::fmin(e.x + dist, side), e.y);
      benchmark::DoNotOptimize(&copy);
    }
  } else {
    for (auto _ : state) {
      SpatialEntry& e = pos[picks[next++ & (picks.size() - 1)]];
      const double to = e.x + dist <= side ? e.x + dist : e.x - dist;
      base.move(e.slot, e.x, e.y, to, e.y);
      e.x = to;
    }
    // Put the base back as it was built.
    const auto& original = points(n);
    for (std::size_t i = 0; i < pos.size(); ++i) {
      if (pos[i].x != original[i].x) {
        base.move(pos[i].slot, pos[i].x, pos[i].y, original[i].x, original[i].y);
      }
    }
  }
}

template <class Policy>
void BM_SpatialIndexInsert(benchmark::State& state) {
  using Index = BasicSpatialIndex<Policy>;
  const std::int64_t n = state.range(0);
  const bool shared = state.range(1) != 0;
  Index& base = Bases<Policy>::get(n);
  PointStream where(side_of(n), 6);
  const auto slot = static_cast<Slot>(n + 1);
  if (shared) {
    for (auto _ : state) {
      const auto [x, y] = where.next();
      Index copy = base;
      copy.insert(slot, x, y);
      benchmark::DoNotOptimize(&copy);
    }
  } else {
    for (auto _ : state) {
      const auto [x, y] = where.next();
      base.insert(slot, x, y);
      base.erase(slot, x, y);
    }
  }
}

void BM_BruteForceWithin(benchmark::State& state) {
  const std::int64_t n = state.range(0);
  const auto& p = points(n);
  PointStream queries(side_of(n), 2);
  std::int64_t found = 0;
  for (auto _ : state) {
    const auto [x, y] = queries.next();
    for (const SpatialEntry& e : p) {
      const double dx = e.x - x;
      const double dy = e.y - y;
      if (dx * dx + dy * dy <= kRange * kRange) {
        ++found;
        benchmark::DoNotOptimize(&e);
      }
    }
  }
  state.counters["results"] =
      static_cast<double>(found) / static_cast<double>(state.iterations());
}

// N = 10^3 .. 10^7 for the default shape (Q1B16), 10^3 .. 10^6 for the others.
void sizes(benchmark::internal::Benchmark* b, std::int64_t top) {
  b->RangeMultiplier(10)->Range(1000, upto(top, 10'000));
}

BENCHMARK(BM_SpatialIndexWithin<Q1B16>)->Apply([](auto* b) { sizes(b, 10'000'000); });
BENCHMARK(BM_SpatialIndexWithin<Q1B8>)->Apply([](auto* b) { sizes(b, 1'000'000); });
BENCHMARK(BM_SpatialIndexWithin<Q2B8>)->Apply([](auto* b) { sizes(b, 1'000'000); });
BENCHMARK(BM_SpatialIndexWithin<Q2B16>)->Apply([](auto* b) { sizes(b, 1'000'000); });
BENCHMARK(BM_SpatialIndexFootprint)->Apply([](auto* b) { sizes(b, 10'000'000); });
BENCHMARK(BM_SpatialIndexNearest)->Apply([](auto* b) { sizes(b, 10'000'000); });
BENCHMARK(BM_BruteForceWithin)->RangeMultiplier(10)->Range(1000, upto(100'000, 10'000));

template <class Policy>
void move_args(benchmark::internal::Benchmark* b, std::int64_t top) {
  for (std::int64_t n = 1000; n <= upto(top, 10'000); n *= 10) {
    for (std::int64_t shared : {0, 1}) {
      for (std::int64_t cm : {5, 500}) {
        b->Args({n, shared, cm});
      }
    }
  }
}
BENCHMARK(BM_SpatialIndexMove<Q1B16>)->Apply([](auto* b) { move_args<Q1B16>(b, 10'000'000); });
BENCHMARK(BM_SpatialIndexMove<Q1B8>)->Apply([](auto* b) { move_args<Q1B8>(b, 1'000'000); });
BENCHMARK(BM_SpatialIndexMove<Q2B8>)->Apply([](auto* b) { move_args<Q2B8>(b, 1'000'000); });
BENCHMARK(BM_SpatialIndexMove<Q2B16>)->Apply([](auto* b) { move_args<Q2B16>(b, 1'000'000); });

template <class Policy>
void insert_args(benchmark::internal::Benchmark* b, std::int64_t top) {
  for (std::int64_t n = 1000; n <= upto(top, 10'000); n *= 10) {
    for (std::int64_t shared : {0, 1}) {
      b->Args({n, shared});
    }
  }
}
BENCHMARK(BM_SpatialIndexInsert<Q1B16>)->Apply([](auto* b) { insert_args<Q1B16>(b, 10'000'000); });
BENCHMARK(BM_SpatialIndexInsert<Q1B8>)->Apply([](auto* b) { insert_args<Q1B8>(b, 1'000'000); });
BENCHMARK(BM_SpatialIndexInsert<Q2B8>)->Apply([](auto* b) { insert_args<Q2B8>(b, 1'000'000); });
BENCHMARK(BM_SpatialIndexInsert<Q2B16>)->Apply([](auto* b) { insert_args<Q2B16>(b, 1'000'000); });

}  // namespace
}  // namespace fastslam::memory
