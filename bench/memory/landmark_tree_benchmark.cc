// Benchmarks of the persistent landmark tree (docs/memory.md has the results and commands).
//
//   BM_LandmarkTreeUpdate<Policy, Heap>/N/shared   one landmark update, ns per update.
//       shared = 1: the map is a fresh copy of a shared base, so the update copies the whole
//       root-to-leaf path, and the copy is released afterwards (freeing that path): the cost a
//       particle pays per landmark after resampling. shared = 0: the map is held alone and the
//       update is in place (lookup + ownership checks).
//   BM_LandmarkTreeFind<Policy, Heap>/N            one lookup of a random slot.
//   BM_LandmarkTreeInsertErase<Policy, Heap>/N     erase a random landmark and insert one (which
//       reuses that slot: the lowest free one), in place; ns per pair.
//   BM_LandmarkTreeCopyRelease/N/k                 copy a handle, update k landmarks, release.
//   BM_LandmarkTreeBytesPerParticle/N/k            100 particles share a base of N landmarks and
//       each updates k: counters bytes_per_particle (tree) and linear_bytes_per_particle.
//   BM_LinearMapUpdate/N/shared                    the same update on a flat std::vector map;
//       shared = 1 copies the whole map first (a particle copy in "linear" FastSLAM).
//   BM_LinearMapBytesPerParticle/N                 bytes a particle's flat map holds.
// The fanout comparison is BM_LandmarkTreeUpdate / Find / InsertErase / BytesPerParticle over
// several TreePolicy shapes at N = 10^6.
// Sizes follow fastslam::bench::upto (FASTSLAM_BENCH_SMOKE=1: tiny sizes for the smoke test).
#include <cstdint>
#include <map>
#include <memory>
#include <random>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench/bench_util.h"
#include "memory/landmark_tree.h"
#include "memory/node_heap.h"

namespace fastslam::memory {
namespace {

using bench::upto;

// Shapes for the fanout comparison (all with the default atomic counts), and the default with
// plain counts to show what the atomics cost.
using I1L0 = TreePolicy<1, 0, AtomicRefcount>;
using I3L1 = TreePolicy<3, 1, AtomicRefcount>;
using I4L2 = DefaultTreePolicy;
using I5L2 = TreePolicy<5, 2, AtomicRefcount>;
using I4L0 = TreePolicy<4, 0, AtomicRefcount>;
using I4L3 = TreePolicy<4, 3, AtomicRefcount>;
using I4L2Local = TreePolicy<4, 2, LocalRefcount>;

Landmark make_landmark(std::uint64_t s) {
  Landmark l;
  l.x = static_cast<double>(s);
  l.y = -static_cast<double>(s);
  l.sxx = l.syy = 1.0;
  l.id = s;
  return l;
}

// Random slots below n, precomputed so the timed loop measures the tree, not the generator.
class SlotStream {
 public:
  SlotStream(std::uint64_t n, std::uint64_t seed) : slots_(kCount) {
    std::mt19937_64 rng(seed);
    for (Slot& s : slots_) s = static_cast<Slot>(rng() % n);
  }
  Slot next() noexcept { return slots_[next_++ & (kCount - 1)]; }

 private:
  static constexpr std::size_t kCount = 1 << 16;
  std::vector<Slot> slots_;
  std::size_t next_ = 0;
};

// Base maps of slots [0, n), built once per (policy, heap, n) and kept for the whole run, so
// that setup does not dominate. Held by one handle: in-place updates of it stay in place.
template <class Policy, class Heap>
class BaseMaps {
 public:
  using Tree = BasicLandmarkTree<Policy>;
  static Heap& heap() {
    static Heap heap;
    return heap;
  }
  static Tree& get(std::uint64_t n) { return *entry(n).tree; }
  // Bytes the base map of n landmarks holds (measured when it was built).
  static std::int64_t bytes(std::uint64_t n) { return entry(n).bytes; }

 private:
  struct Entry {
    std::unique_ptr<Tree> tree;
    std::int64_t bytes = 0;
  };
  static Entry& entry(std::uint64_t n) {
    Heap& h = heap();  // constructed before (so destroyed after) the cache below
    static std::map<std::uint64_t, Entry> cache;
    Entry& e = cache[n];
    if (!e.tree) {
      const std::int64_t before = h.stats().live_bytes;
      e.tree = std::make_unique<Tree>(h);
      for (std::uint64_t s = 0; s < n; ++s) e.tree->insert(make_landmark(s));
      e.bytes = h.stats().live_bytes - before;
    }
    return e;
  }
};

template <class Policy, class Heap>
void BM_LandmarkTreeUpdate(benchmark::State& state) {
  using Tree = BasicLandmarkTree<Policy>;
  const auto n = static_cast<std::uint64_t>(state.range(0));
  const bool shared = state.range(1) != 0;
  Tree& base = BaseMaps<Policy, Heap>::get(n);
  SlotStream slots(n, 1);
  if (shared) {
    for (auto _ : state) {
      Tree copy = base;  // O(1); the edit below copies the path, the destructor frees it
      Landmark& l = copy.edit(slots.next());
      l.x += 1.0;
      benchmark::DoNotOptimize(&l);
    }
  } else {
    for (auto _ : state) {
      Landmark& l = base.edit(slots.next());
      l.x += 1.0;
      benchmark::DoNotOptimize(&l);
    }
  }
  state.counters["height"] = base.height();
}

template <class Policy, class Heap>
void BM_LandmarkTreeFind(benchmark::State& state) {
  const auto n = static_cast<std::uint64_t>(state.range(0));
  const auto& base = BaseMaps<Policy, Heap>::get(n);
  SlotStream slots(n, 2);
  double sum = 0.0;
  for (auto _ : state) {
    const Landmark* l = base.find(slots.next());
    if (l != nullptr) sum += l->x;  // always held; the test keeps -Wnull-dereference quiet
  }
  benchmark::DoNotOptimize(sum);
}

template <class Policy, class Heap>
void BM_LandmarkTreeInsertErase(benchmark::State& state) {
  const auto n = static_cast<std::uint64_t>(state.range(0));
  auto& base = BaseMaps<Policy, Heap>::get(n);
  SlotStream slots(n, 3);
  for (auto _ : state) {
    const Slot s = slots.next();
    base.erase(s);
    const Slot again = base.insert(make_landmark(s));  // the lowest free slot: s again
    benchmark::DoNotOptimize(again);
  }
}

template <class Policy, class Heap>
void BM_LandmarkTreeCopyRelease(benchmark::State& state) {
  using Tree = BasicLandmarkTree<Policy>;
  const auto n = static_cast<std::uint64_t>(state.range(0));
  const auto k = state.range(1);
  const Tree& base = BaseMaps<Policy, Heap>::get(n);
  SlotStream slots(n, 4);
  for (auto _ : state) {
    Tree copy = base;
    for (std::int64_t u = 0; u < k; ++u) copy.edit(slots.next()).x += 1.0;
    benchmark::DoNotOptimize(copy.find(0));
  }
  state.counters["ns_per_update"] =
      benchmark::Counter(static_cast<double>(state.iterations() * k),
                         benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}

// 100 particles share a base of N landmarks; each updates k random landmarks. Reports the
// bytes each particle adds to the one shared map (its copied paths), against the N * 64 bytes
// of a flat per-particle map. Timing: building the 100 copies (path copying), then releasing.
template <class Policy, class Heap>
void BM_LandmarkTreeBytesPerParticle(benchmark::State& state) {
  using Tree = BasicLandmarkTree<Policy>;
  constexpr int kParticles = 100;
  const auto n = static_cast<std::uint64_t>(state.range(0));
  const auto k = state.range(1);
  const Tree& base = BaseMaps<Policy, Heap>::get(n);
  Heap& heap = BaseMaps<Policy, Heap>::heap();
  double bytes = 0.0;
  double nodes = 0.0;
  for (auto _ : state) {
    SlotStream slots(n, 5);  // the same updates every iteration: deterministic counters
    const HeapStats before = heap.stats();
    std::vector<Tree> particles(kParticles, base);
    for (Tree& particle : particles) {
      for (std::int64_t u = 0; u < k; ++u) particle.edit(slots.next()).x += 1.0;
    }
    const HeapStats after = heap.stats();
    bytes = static_cast<double>(after.live_bytes - before.live_bytes) / kParticles;
    nodes = static_cast<double>(after.live_nodes - before.live_nodes) / kParticles;
  }
  state.counters["bytes_per_particle"] = bytes;
  state.counters["nodes_per_particle"] = nodes;
  state.counters["linear_bytes_per_particle"] = static_cast<double>(n * sizeof(Landmark));
  state.counters["base_bytes_per_landmark"] =
      static_cast<double>(BaseMaps<Policy, Heap>::bytes(n)) / static_cast<double>(n);
}

// The baseline: a flat map per particle ("linear" FastSLAM). shared = 1: the particle's map was
// just resampled from another's, so the update copies the whole map first.
void BM_LinearMapUpdate(benchmark::State& state) {
  const auto n = static_cast<std::uint64_t>(state.range(0));
  const bool shared = state.range(1) != 0;
  std::vector<Landmark> base(n);
  for (std::uint64_t s = 0; s < n; ++s) base[s] = make_landmark(s);
  SlotStream slots(n, 1);
  if (shared) {
    for (auto _ : state) {
      std::vector<Landmark> copy = base;
      copy[slots.next()].x += 1.0;
      benchmark::DoNotOptimize(copy.data());
    }
  } else {
    for (auto _ : state) {
      Landmark& l = base[slots.next()];
      l.x += 1.0;
      benchmark::DoNotOptimize(&l);
    }
  }
}

void BM_LinearMapBytesPerParticle(benchmark::State& state) {
  const auto n = static_cast<std::uint64_t>(state.range(0));
  const std::vector<Landmark> base(n);
  double bytes = 0.0;
  for (auto _ : state) {
    std::vector<Landmark> particle = base;  // a particle copy is a whole map copy
    bytes = static_cast<double>(particle.capacity() * sizeof(Landmark));
    benchmark::DoNotOptimize(particle.data());
  }
  state.counters["bytes_per_particle"] = bytes;
}

// ---------------------------------------------------------------------------------------------
// Registration

const std::int64_t kMaxN = upto(10'000'000, 1000);
const std::int64_t kMaxLinearN = upto(1'000'000, 1000);
const std::int64_t kFanoutN = upto(1'000'000, 1000);

void sweep_shared(benchmark::internal::Benchmark* b, std::int64_t max_n) {
  for (std::int64_t n = 100; n <= max_n; n *= 10) {
    b->Args({n, 1});
    b->Args({n, 0});
  }
  b->ArgNames({"N", "shared"});
}

#define FASTSLAM_SWEEP(max_n) \
  Apply([](benchmark::internal::Benchmark* b) { sweep_shared(b, max_n); })

// ns per update against N, shared and unshared, both heaps; the flat baseline.
BENCHMARK_TEMPLATE(BM_LandmarkTreeUpdate, I4L2, PoolHeap)->FASTSLAM_SWEEP(kMaxN);
BENCHMARK_TEMPLATE(BM_LandmarkTreeUpdate, I4L2, MallocHeap)->FASTSLAM_SWEEP(kMaxN);
BENCHMARK(BM_LinearMapUpdate)->FASTSLAM_SWEEP(kMaxLinearN);
BENCHMARK_TEMPLATE(BM_LandmarkTreeFind, I4L2, PoolHeap)
    ->RangeMultiplier(10)
    ->Range(100, kMaxN)
    ->ArgName("N");

BENCHMARK_TEMPLATE(BM_LandmarkTreeCopyRelease, I4L2, PoolHeap)
    ->ArgsProduct({{1000, kFanoutN}, {1, 10, 100}})
    ->ArgNames({"N", "k"});

// Bytes per particle after k updates, tree against flat.
BENCHMARK_TEMPLATE(BM_LandmarkTreeBytesPerParticle, I4L2, MallocHeap)
    ->ArgsProduct({{upto(10'000, 1000), upto(1'000'000, 1000)}, {1, 10, 100, 1000}})
    ->ArgNames({"N", "k"})
    ->Iterations(3);
BENCHMARK(BM_LinearMapBytesPerParticle)
    ->RangeMultiplier(100)
    ->Range(upto(10'000, 1000), upto(1'000'000, 1000))
    ->ArgName("N")
    ->Iterations(3);

// The fanout comparison at N = 10^6.
#define FASTSLAM_FANOUT(Policy)                                                                  \
  BENCHMARK_TEMPLATE(BM_LandmarkTreeUpdate, Policy, PoolHeap)                                    \
      ->Args({kFanoutN, 1})                                                                      \
      ->Args({kFanoutN, 0})                                                                      \
      ->ArgNames({"N", "shared"});                                                               \
  BENCHMARK_TEMPLATE(BM_LandmarkTreeFind, Policy, PoolHeap)->Arg(kFanoutN)->ArgName("N");        \
  BENCHMARK_TEMPLATE(BM_LandmarkTreeInsertErase, Policy, PoolHeap)->Arg(kFanoutN)->ArgName("N"); \
  BENCHMARK_TEMPLATE(BM_LandmarkTreeBytesPerParticle, Policy, MallocHeap)                        \
      ->Args({kFanoutN, 10})                                                                     \
      ->ArgNames({"N", "k"})                                                                     \
      ->Iterations(3)

FASTSLAM_FANOUT(I1L0);
FASTSLAM_FANOUT(I3L1);
FASTSLAM_FANOUT(I4L0);
FASTSLAM_FANOUT(I4L3);
FASTSLAM_FANOUT(I5L2);
FASTSLAM_FANOUT(I4L2Local);
// I4L2 (the default) at N = 10^6 is part of the sweeps above; its insert/erase here.
BENCHMARK_TEMPLATE(BM_LandmarkTreeInsertErase, I4L2, PoolHeap)->Arg(kFanoutN)->ArgName("N");

}  // namespace
}  // namespace fastslam::memory
