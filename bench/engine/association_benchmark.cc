// Unknown data association against map size (issue: "flat within 2x from 10^3 to 10^6"): the
// time of a scan update (the queued controls, then candidates from the spatial index, gating,
// ML choice with mutual exclusion, EKF updates, negative information, resampling) with M = 100
// particles whose maps hold N landmarks at constant density (a grid world, one landmark per
// 10 m x 10 m), N = 10^3 ... 10^6.
//
// Setup, not timed: the grid world, `scans` scans simulated along its first lane, and a filter
// whose particles all share the true map as a prior (Filter::set_map; covariance 0.1 m^2, high
// existence log-odds). Timed: feeding the controls and scans. Reported: seconds per scan
// (the iteration time divided by the scans) and the live tree bytes at the end.
//
// Args: algorithm (1, 2), N, threads. Under FASTSLAM_BENCH_SMOKE=1: N = 10^3, 60 scans.
#include <chrono>
#include <cstdint>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench/bench_util.h"
#include "engine/filter.h"
#include "tools/simulator.h"
#include "tools/world.h"

namespace fastslam::engine {
namespace {

struct Step {
  Control control;
  double dt = 0.0;
  bool has_scan = false;
  std::vector<Observation> scan;
};

std::vector<Step> simulate(const tools::World& world, std::int64_t scans) {
  tools::Simulator sim(world, tools::SimConfig{}, 1);
  tools::SimStep s;
  std::vector<Step> out;
  std::int64_t seen = 0;
  while (seen < scans && sim.next(s)) {
    Step step{{s.speed, s.steer}, s.dt, s.has_scan, {}};
    for (const tools::SimObservation& z : s.scan) step.scan.push_back({z.range, z.bearing, -1});
    seen += s.has_scan ? 1 : 0;
    out.push_back(std::move(step));
  }
  return out;
}

void BM_UnknownAssociationScaling(benchmark::State& state) {
  const auto n = static_cast<std::uint64_t>(state.range(1));
  const std::int64_t scans = bench::upto(500, 60);
  const tools::World world = tools::make_grid_world(n, 10.0, 45.0, 1);
  const std::vector<Step> steps = simulate(world, scans);
  std::vector<MapLandmark> prior;
  prior.reserve(world.landmarks.size());
  for (std::size_t i = 0; i < world.landmarks.size(); ++i) {
    prior.push_back({0, i, world.landmarks[i].x, world.landmarks[i].y, 0.1, 0.0, 0.1, 50.0, 0});
  }
  FilterConfig config;
  config.algorithm = state.range(0) == 1 ? Algorithm::kFastSlam1 : Algorithm::kFastSlam2;
  config.association = Association::kMaximumLikelihood;
  config.particles = 100;
  config.threads = static_cast<unsigned>(state.range(2));
  config.seed = 1;
  config.initial_pose[0] = world.start_x;
  config.initial_pose[1] = world.start_y;
  config.initial_pose[2] = world.start_theta;
  std::int64_t live_bytes = 0;
  std::uint64_t observations = 0;
  for (auto _ : state) {
    Filter filter(config);
    filter.set_map(prior);
    const auto t0 = std::chrono::steady_clock::now();
    for (const Step& step : steps) {
      filter.predict(step.control, step.dt);
      if (step.has_scan) filter.observe(step.scan);
    }
    benchmark::DoNotOptimize(filter.estimate().mean_pose[0]);
    state.SetIterationTime(
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    live_bytes = filter.statistics().live_bytes;
    observations = filter.statistics().observations;
  }
  state.counters["per_scan"] = benchmark::Counter(
      static_cast<double>(scans),
      benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.counters["observations_per_scan"] =
      static_cast<double>(observations) / static_cast<double>(scans);
  state.counters["live_MiB"] = static_cast<double>(live_bytes) / (1 << 20);
}

void scaling_args(benchmark::internal::Benchmark* b) {
  const std::int64_t max_n = bench::upto(1'000'000, 1'000);
  for (const std::int64_t algorithm : {1, 2}) {
    for (std::int64_t n = 1'000; n <= max_n; n *= 10) b->Args({algorithm, n, 1});
  }
}

BENCHMARK(BM_UnknownAssociationScaling)
    ->ArgNames({"fastslam", "landmarks", "threads"})
    ->Apply(scaling_args)
    ->Unit(benchmark::kMillisecond)
    ->UseManualTime()
    ->Iterations(1);

}  // namespace
}  // namespace fastslam::engine
