// Resampling benchmarks: the draw (normalise, N_eff, cumulative weights, merge) per scheme over
// M = 10^2 .. 10^7 and 1 / 2 threads, a grain sweep, and the whole engine call on a particle
// store (draw + gather + release of dead maps). Under FASTSLAM_BENCH_SMOKE=1 sizes stop at 10^3.
//   BM_SystematicResample/M/threads      summarize + systematic draw of M indices
//   BM_StratifiedResample, BM_MultinomialResample   the same for the other schemes
//   BM_SystematicResampleGrain/M/grain   2 threads, grain swept (the default is 512)
//   BM_ResampleStore/M/threads           Resampler::resample on a store with 8 landmarks each
#include <algorithm>
#include <cstdint>
#include <random>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench/bench_util.h"
#include "memory/node_heap.h"
#include "memory/particle_store.h"
#include "parallel/particle_kernel.h"
#include "parallel/resample.h"

namespace fastslam::parallel {
namespace {

std::vector<std::int64_t> sizes(std::int64_t full, std::int64_t tiny) {
  std::vector<std::int64_t> v;
  for (std::int64_t m = 100; m <= bench::upto(full, tiny); m *= 10) {
    v.push_back(m);
  }
  return v;
}

std::vector<double> log_weights(std::size_t m) {
  std::mt19937_64 gen(m);
  std::normal_distribution<double> normal(0.0, 2.0);
  std::vector<double> l(m);
  for (double& v : l) {
    v = normal(gen);
  }
  return l;
}

void run_draw(benchmark::State& state, ResampleScheme scheme, unsigned threads, std::size_t grain) {
  const auto m = static_cast<std::size_t>(state.range(0));
  const ParticleKernel kernel({.threads = threads, .grain = grain});
  const std::vector<double> l = log_weights(m);
  std::vector<std::uint32_t> out(m);
  Resampler resampler({.scheme = scheme}, kernel);
  std::uint64_t step = 0;
  for (auto _ : state) {
    resampler.summarize(l);
    resampler.draw(scheme, 7, step++, out);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(m));
}

void BM_SystematicResample(benchmark::State& state) {
  run_draw(state, ResampleScheme::kSystematic, static_cast<unsigned>(state.range(1)),
           KernelConfig{}.grain);
}
void BM_StratifiedResample(benchmark::State& state) {
  run_draw(state, ResampleScheme::kStratified, static_cast<unsigned>(state.range(1)),
           KernelConfig{}.grain);
}
void BM_MultinomialResample(benchmark::State& state) {
  run_draw(state, ResampleScheme::kMultinomial, static_cast<unsigned>(state.range(1)),
           KernelConfig{}.grain);
}
void BM_SystematicResampleGrain(benchmark::State& state) {
  run_draw(state, ResampleScheme::kSystematic, 2, static_cast<std::size_t>(state.range(1)));
}

void BM_ResampleStore(benchmark::State& state) {
  const auto m = static_cast<std::size_t>(state.range(0));
  const ParticleKernel kernel({.threads = static_cast<unsigned>(state.range(1))});
  memory::PoolHeap heap;
  memory::ParticleStore store(m, heap);
  const std::vector<double> l = log_weights(m);
  for (std::size_t i = 0; i < m; ++i) {
    for (int k = 0; k < 8; ++k) {
      store.map(i).insert({.x = static_cast<double>(i)}, 0.0f);
    }
  }
  Resampler resampler({}, kernel);
  std::uint64_t step = 0;
  for (auto _ : state) {
    std::copy(l.begin(), l.end(), store.log_weight().begin());
    resampler.resample(store, 7, step++);
    benchmark::DoNotOptimize(store.x().data());
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(m));
}

BENCHMARK(BM_SystematicResample)
    ->ArgsProduct({sizes(10'000'000, 1000), {1, 2}})
    ->ArgNames({"M", "threads"})
    ->UseRealTime()
    ->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_StratifiedResample)
    ->ArgsProduct({sizes(1'000'000, 1000), {1, 2}})
    ->ArgNames({"M", "threads"})
    ->UseRealTime()
    ->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_MultinomialResample)
    ->ArgsProduct({sizes(1'000'000, 1000), {1, 2}})
    ->ArgNames({"M", "threads"})
    ->UseRealTime()
    ->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_SystematicResampleGrain)
    ->ArgsProduct({sizes(1'000'000, 1000), {256, 512, 1024, 2048, 4096, 8192}})
    ->ArgNames({"M", "grain"})
    ->UseRealTime()
    ->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_ResampleStore)
    ->ArgsProduct({sizes(1'000'000, 1000), {1, 2}})
    ->ArgNames({"M", "threads"})
    ->UseRealTime()
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace fastslam::parallel
