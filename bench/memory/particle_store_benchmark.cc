// Benchmarks of the particle store's resampling step (docs/memory.md has the results).
//
//   BM_ParticleStoreGather/M/threads/edited   one gather of M particles in a task_arena of
//       `threads` threads. edited = 0: every map is the same shared root, so a gather copies
//       the columns and moves root counts only. edited = 1: before each gather (untimed) every
//       particle's map is reset to a 10^4-landmark base map and updates 10 landmarks of it, so
//       the gather also frees the copied paths of the particles that die (about a third).
//       items_per_second counts particles.
// Sizes follow fastslam::bench::upto (FASTSLAM_BENCH_SMOKE=1: tiny sizes for the smoke test).
#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

#include <benchmark/benchmark.h>
#include <oneapi/tbb/global_control.h>
#include <oneapi/tbb/task_arena.h>

#include "bench/bench_util.h"
#include "memory/landmark_tree.h"
#include "memory/node_heap.h"
#include "memory/particle_store.h"

namespace fastslam::memory {
namespace {

using bench::upto;

// Sorted multinomial ancestors: what systematic resampling produces (some particles repeated,
// about a third gone).
std::vector<std::uint32_t> resample_index(std::size_t m, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<std::uint32_t> index(m);
  for (auto& i : index) i = static_cast<std::uint32_t>(rng() % m);
  std::sort(index.begin(), index.end());
  return index;
}

void BM_ParticleStoreGather(benchmark::State& state) {
  const auto m = static_cast<std::size_t>(state.range(0));
  const int threads = static_cast<int>(state.range(1));
  const bool edited = state.range(2) != 0;
  const std::uint64_t n = upto(10'000, 100);
  PoolHeap heap;
  LandmarkTree base(heap);
  for (std::uint64_t s = 0; s < n; ++s) base.insert(Landmark{});
  ParticleStore store(m, heap);
  const ParticleMap base_map(base, Indexing::kNone, [](const Landmark&) { return 0.0f; });
  for (std::size_t k = 0; k < m; ++k) store.map(k) = base_map;
  const std::vector<std::uint32_t> index = resample_index(m, 7);
  std::mt19937_64 rng(3);
  tbb::global_control workers(tbb::global_control::max_allowed_parallelism,
                              static_cast<std::size_t>(std::max(threads, 2)));
  tbb::task_arena arena(threads);
  arena.execute([&] {
    for (auto _ : state) {
      if (edited) {  // the same state before every gather: base + 10 own paths per particle
        state.PauseTiming();
        for (std::size_t k = 0; k < m; ++k) {
          store.map(k) = base_map;
          for (int u = 0; u < 10; ++u) {
            store.map(k).edit_unindexed(static_cast<Slot>(rng() % n)).x += 1.0;
          }
        }
        state.ResumeTiming();
      }
      store.gather(index);
    }
  });
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(m));
}

BENCHMARK(BM_ParticleStoreGather)
    ->ArgsProduct({benchmark::CreateRange(100, upto(100'000, 1000), 10), {1, 2}, {0, 1}})
    ->ArgNames({"M", "threads", "edited"})
    ->UseRealTime();

}  // namespace
}  // namespace fastslam::memory
