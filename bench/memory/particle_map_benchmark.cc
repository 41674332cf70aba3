// Benchmarks of ParticleMap's changes against the same work done by hand on a bare tree and
// index (what the engine did before the map owned the invariant); docs/memory.md has results.
//
//   BM_ParticleMapUpdate/N/moves      one update of a random landmark of an indexed map of N
//       landmarks whose nodes another map shares (so every update copies paths, as after
//       resampling): moves = 1 shifts the mean by up to 1 m (the index entry moves), moves = 0
//       changes the log-odds only.
//   BM_TreeAndIndexUpdate/N/moves     the same by hand: tree.edit, change in place, index.move
//       when the mean changed.
//   BM_ParticleMapInsertErase/N       insert one landmark into an indexed map of N and erase it.
// Sizes follow fastslam::bench::upto (FASTSLAM_BENCH_SMOKE=1: tiny sizes for the smoke test).
#include <cmath>
#include <cstdint>
#include <random>

#include <benchmark/benchmark.h>

#include "bench/bench_util.h"
#include "memory/landmark_tree.h"
#include "memory/node_heap.h"
#include "memory/particle_map.h"
#include "memory/spatial_index.h"

namespace fastslam::memory {
namespace {

using bench::upto;

float extent_of(const Landmark& l) { return static_cast<float>(l.sxx); }

LandmarkTree random_tree(NodeHeap& heap, std::int64_t n, std::mt19937_64& rng) {
  const double side = 10.0 * std::sqrt(static_cast<double>(n));
  std::uniform_real_distribution<double> at(-side / 2, side / 2);
  LandmarkTree tree(heap);
  for (std::int64_t i = 0; i < n; ++i) {
    tree.insert({.x = at(rng), .y = at(rng), .sxx = 1.0, .syy = 1.0});
  }
  return tree;
}

void BM_ParticleMapUpdate(benchmark::State& state) {
  const std::int64_t n = state.range(0);
  const bool moves = state.range(1) != 0;
  PoolHeap heap;
  std::mt19937_64 rng(1);
  const ParticleMap base(random_tree(heap, n, rng), Indexing::kSpatial, extent_of);
  ParticleMap map = base;
  std::uniform_real_distribution<double> step(-1.0, 1.0);
  std::int64_t k = 0;
  for (auto _ : state) {
    if (++k % 64 == 0) map = base;  // keep the nodes shared
    const auto slot = static_cast<Slot>(rng() % static_cast<std::uint64_t>(n));
    const double dx = moves ? step(rng) : 0.0;
    map.update(
        slot,
        [&](Landmark& l) {
          l.x += dx;
          l.log_odds += 0.1;
        },
        extent_of);
  }
}

void BM_TreeAndIndexUpdate(benchmark::State& state) {
  const std::int64_t n = state.range(0);
  const bool moves = state.range(1) != 0;
  PoolHeap heap;
  std::mt19937_64 rng(1);
  const LandmarkTree base_tree = random_tree(heap, n, rng);
  SpatialIndex base_index(heap);
  for (const auto [slot, l] : base_tree) base_index.insert(slot, l.x, l.y, extent_of(l));
  LandmarkTree tree = base_tree;
  SpatialIndex index = base_index;
  std::uniform_real_distribution<double> step(-1.0, 1.0);
  std::int64_t k = 0;
  for (auto _ : state) {
    if (++k % 64 == 0) {
      tree = base_tree;
      index = base_index;
    }
    const auto slot = static_cast<Slot>(rng() % static_cast<std::uint64_t>(n));
    const double dx = moves ? step(rng) : 0.0;
    Landmark& l = tree.edit(slot);
    const double from_x = l.x, from_y = l.y;
    l.x += dx;
    l.log_odds += 0.1;
    if (l.x != from_x || l.y != from_y) index.move(slot, from_x, from_y, l.x, l.y, extent_of(l));
  }
}

void BM_ParticleMapInsertErase(benchmark::State& state) {
  const std::int64_t n = state.range(0);
  PoolHeap heap;
  std::mt19937_64 rng(2);
  ParticleMap map(random_tree(heap, n, rng), Indexing::kSpatial, extent_of);
  for (auto _ : state) {
    const Slot slot = map.insert({.x = 3.0, .y = -7.0, .sxx = 1.0, .syy = 1.0}, 1.0f);
    map.erase(slot);
  }
}

const std::int64_t kMaxN = upto(1'000'000, 1000);

BENCHMARK(BM_ParticleMapUpdate)->ArgsProduct({benchmark::CreateRange(1000, kMaxN, 100), {0, 1}});
BENCHMARK(BM_TreeAndIndexUpdate)->ArgsProduct({benchmark::CreateRange(1000, kMaxN, 100), {0, 1}});
BENCHMARK(BM_ParticleMapInsertErase)->RangeMultiplier(100)->Range(1000, kMaxN);

}  // namespace
}  // namespace fastslam::memory
