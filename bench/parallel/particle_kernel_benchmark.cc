// Overhead of the per-particle kernel over M = 10^2 .. 10^7 and 1 / 2 threads (default grain).
// Under FASTSLAM_BENCH_SMOKE=1 sizes stop at 10^3.
//   BM_ParticleKernelEmpty/M/threads    for_each_particle with an empty body per particle: what
//                                       the kernel itself costs (arena entry, tasks, the loop)
//   BM_ParticleKernelReduce/M/threads   the deterministic reduce summing one column
#include <cstdint>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench/bench_util.h"
#include "parallel/particle_kernel.h"

namespace fastslam::parallel {
namespace {

std::vector<std::int64_t> sizes(std::int64_t full, std::int64_t tiny) {
  std::vector<std::int64_t> v;
  for (std::int64_t m = 100; m <= bench::upto(full, tiny); m *= 10) {
    v.push_back(m);
  }
  return v;
}

void BM_ParticleKernelEmpty(benchmark::State& state) {
  const auto m = static_cast<std::size_t>(state.range(0));
  const ParticleKernel kernel({.threads = static_cast<unsigned>(state.range(1))});
  for (auto _ : state) {
    kernel.for_each_particle(m, [](std::size_t i) { benchmark::DoNotOptimize(i); });
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(m));
}

void BM_ParticleKernelReduce(benchmark::State& state) {
  const auto m = static_cast<std::size_t>(state.range(0));
  const ParticleKernel kernel({.threads = static_cast<unsigned>(state.range(1))});
  const std::vector<double> column(m, 0.5);
  for (auto _ : state) {
    const double sum = kernel.reduce(
        m, 0.0,
        [&](std::size_t begin, std::size_t end) {
          double s = 0.0;
          for (std::size_t i = begin; i < end; ++i) {
            s += column[i];
          }
          return s;
        },
        [](double a, double b) { return a + b; });
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(m));
}

BENCHMARK(BM_ParticleKernelEmpty)
    ->ArgsProduct({sizes(10'000'000, 1000), {1, 2}})
    ->ArgNames({"M", "threads"})
    ->UseRealTime()
    ->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_ParticleKernelReduce)
    ->ArgsProduct({sizes(10'000'000, 1000), {1, 2}})
    ->ArgNames({"M", "threads"})
    ->UseRealTime()
    ->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace fastslam::parallel
