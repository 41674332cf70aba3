// Data association against map size (issue: "flat within 2x from 10^3 to 10^6"): the time of a
// scan update (the queued controls, then, unknown association, candidates from the spatial
// index, gating, ML choice with mutual exclusion; EKF updates, negative information,
// resampling) with M = 100 particles whose maps hold N landmarks at constant density (a grid
// world, one landmark per 10 m x 10 m), N = 10^3 ... 10^6, known and ML association.
//
// Setup and timing are tools/studies/scaling_study.h's (`fastslam bench scaling` runs the same
// study): a grid world, scans simulated along its first lane, particles sharing the true map as a
// prior (Filter::set_map); timed: feeding the controls and scans. Reported: time per scan, live
// bytes at the end and the bytes of one map.
//
// Args: algorithm (1, 2), association (0 known, 1 ML), N, threads. Under FASTSLAM_BENCH_SMOKE=1:
// N = 10^3, 60 scans. Google Benchmark's JSON: --benchmark_out=F --benchmark_out_format=json
// (docs/scaling.md).
#include <cstdint>

#include <benchmark/benchmark.h>

#include "bench/bench_util.h"
#include "engine/filter_config.h"
#include "tools/studies/scaling_study.h"

namespace fastslam::engine {
namespace {

// One point of the scaling study (tools/studies/scaling_study.h), which owns the setup and the
// timing.
void BM_AssociationScaling(benchmark::State& state) {
  tools::ScalingOptions options;
  options.updates = static_cast<std::uint64_t>(bench::upto(500, 60));
  options.filter.algorithm = state.range(0) == 1 ? Algorithm::kFastSlam1 : Algorithm::kFastSlam2;
  options.filter.association =
      state.range(1) == 0 ? Association::kKnown : Association::kMaximumLikelihood;
  options.filter.particles = 100;
  options.filter.threads = static_cast<unsigned>(state.range(3));
  options.filter.seed = 1;
  tools::ScalingPoint p;
  for (auto _ : state) {
    p = tools::run_scaling_point(options, static_cast<std::uint64_t>(state.range(2)));
    state.SetIterationTime(p.seconds);
  }
  state.counters["per_scan"] = benchmark::Counter(
      static_cast<double>(p.updates),
      benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.counters["observations_per_scan"] =
      static_cast<double>(p.observations) / static_cast<double>(p.updates);
  state.counters["live_MiB"] = static_cast<double>(p.live_bytes) / (1 << 20);
  state.counters["one_map_MiB"] = static_cast<double>(p.lower_bound_bytes) / (1 << 20);
  state.counters["ns_per_particle_observation"] =
      1e9 * p.seconds / (static_cast<double>(p.observations) * options.filter.particles);
}

void scaling_args(benchmark::internal::Benchmark* b) {
  const std::int64_t max_n = bench::upto(1'000'000, 1'000);
  for (const std::int64_t algorithm : {1, 2}) {
    for (const std::int64_t association : {0, 1}) {
      for (std::int64_t n = 1'000; n <= max_n; n *= 10) b->Args({algorithm, association, n, 1});
    }
  }
}

BENCHMARK(BM_AssociationScaling)
    ->ArgNames({"fastslam", "ml", "landmarks", "threads"})
    ->Apply(scaling_args)
    ->Unit(benchmark::kMillisecond)
    ->UseManualTime()
    ->Iterations(1);

}  // namespace
}  // namespace fastslam::engine
