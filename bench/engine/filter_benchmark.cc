// Wall time of the whole Filter loop on Bailey's webmap (17382 controls, 1931 scans, 35
// landmarks, known association): FastSLAM 1.0 and 2.0, M = 100, 1000, 10000 particles, 1 and 2
// threads. The controls and scans are simulated once, before timing, so an iteration is only
// the filter: construct, predict/observe every step, estimate. Reported time per iteration =
// seconds per whole run (use --benchmark_repetitions=3 and the medians).
//
// Needs ../shared/data/bailey_sim (FASTSLAM_SHARED_DIR, ../shared, or the one beside the
// source tree); skipped with a message otherwise. Under FASTSLAM_BENCH_SMOKE=1 the particle
// count is tiny.
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench/bench_util.h"
#include "engine/filter.h"
#include "tools/sim/simulator.h"
#include "tools/sim/world.h"

namespace fastslam::engine {
namespace {

struct Step {
  Control control;
  double dt = 0.0;
  std::vector<Observation> scan;  // empty: no scan after this control
  bool has_scan = false;
};

std::string find_bailey_dir() {
  std::vector<std::string> candidates;
  if (const char* dir = std::getenv("FASTSLAM_SHARED_DIR")) candidates.emplace_back(dir);
  candidates.emplace_back("../shared");
#ifdef FASTSLAM_SOURCE_DIR
  candidates.emplace_back(std::string(FASTSLAM_SOURCE_DIR) + "/../shared");
#endif
  for (const std::string& c : candidates) {
    const std::string dir = c + "/data/bailey_sim";
    if (std::filesystem::is_regular_file(dir + "/example_webmap_landmarks.csv")) return dir;
  }
  return {};
}

// The webmap run of Bailey's simulator with its defaults (seed 1), or empty without the data.
const std::vector<Step>& webmap_steps() {
  static const std::vector<Step> steps = [] {
    std::vector<Step> out;
    const std::string dir = find_bailey_dir();
    if (dir.empty()) return out;
    const tools::World world = tools::read_world_csv(dir + "/example_webmap_landmarks.csv",
                                                     dir + "/example_webmap_waypoints.csv");
    tools::Simulator sim(world, tools::SimConfig{}, 1);
    tools::SimStep s;
    while (sim.next(s)) {
      Step step;
      step.control = {s.speed, s.steer};
      step.dt = s.dt;
      step.has_scan = s.has_scan;
      for (const tools::SimObservation& z : s.scan) {
        step.scan.push_back({z.range, z.bearing, static_cast<std::int64_t>(z.landmark)});
      }
      out.push_back(std::move(step));
    }
    return out;
  }();
  return steps;
}

// Args: algorithm (1 or 2), particles, threads.
void BM_FilterWebmap(benchmark::State& state) {
  const std::vector<Step>& steps = webmap_steps();
  if (steps.empty()) {
    state.SkipWithError("../shared/data/bailey_sim is absent (set FASTSLAM_SHARED_DIR)");
    return;
  }
  FilterConfig config;
  config.algorithm = state.range(0) == 1 ? Algorithm::kFastSlam1 : Algorithm::kFastSlam2;
  config.particles = static_cast<std::uint32_t>(state.range(1));
  config.threads = static_cast<unsigned>(state.range(2));
  config.seed = 1;
  std::uint64_t scans = 0;
  for (auto _ : state) {
    Filter filter(config);
    for (const Step& step : steps) {
      filter.predict(step.control, step.dt);
      if (step.has_scan) filter.observe(step.scan);
    }
    const Estimate e = filter.estimate();
    benchmark::DoNotOptimize(e.mean_pose[0]);
    scans = filter.statistics().scans;
  }
  state.counters["scans"] = static_cast<double>(scans);
  state.counters["particle_steps/s"] =
      benchmark::Counter(static_cast<double>(steps.size()) * static_cast<double>(config.particles),
                         benchmark::Counter::kIsIterationInvariantRate);
}

void webmap_args(benchmark::internal::Benchmark* b) {
  const std::int64_t max_particles = fastslam::bench::upto(10000, 10);
  for (const std::int64_t algorithm : {1, 2}) {
    for (std::int64_t particles = fastslam::bench::smoke() ? 10 : 100; particles <= max_particles;
         particles *= 10) {
      for (const std::int64_t threads : {1, 2}) b->Args({algorithm, particles, threads});
    }
  }
}

BENCHMARK(BM_FilterWebmap)
    ->ArgNames({"fastslam", "particles", "threads"})
    ->Apply(webmap_args)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

}  // namespace
}  // namespace fastslam::engine
