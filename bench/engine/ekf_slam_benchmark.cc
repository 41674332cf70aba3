// The cost of EKF-SLAM against the map size N, to see where it stops being practical: one
// observation of a known landmark (an O(n^2) covariance update, n = 3 + 2N), the same with
// maximum-likelihood association (scoring the observation against all N landmarks first), and
// one prediction (O(N)). The map is built before timing: N landmarks around the vehicle, seen
// once each after some driving, so the pose and every landmark are correlated.
// Under FASTSLAM_BENCH_SMOKE=1 only N = 10 runs.
#include <cmath>
#include <cstdint>
#include <numbers>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench/bench_util.h"
#include "engine/ekf_slam.h"

namespace fastslam::engine {
namespace {

// Landmark i on a spiral 8..40 m around the origin.
Observation observation_of(std::int64_t i, std::int64_t n) {
  const double t = static_cast<double>(i) / static_cast<double>(n);
  const double range = 8.0 + 32.0 * t;
  const double bearing = std::remainder(2.0 * std::numbers::pi * 37.0 * t, 2.0 * std::numbers::pi);
  return {range, bearing, i};
}

EkfSlam make_map(Association association, std::int64_t landmarks) {
  FilterConfig config;
  config.algorithm = Algorithm::kEkf;
  config.association = association;
  EkfSlam ekf(config);
  ekf.reserve(static_cast<std::size_t>(landmarks));
  // Drive a little (pose uncertainty), then see all landmarks in scans of 10, then come back.
  for (int k = 0; k < 20; ++k) ekf.predict({1.0, 0.0}, 0.05);
  for (int k = 0; k < 20; ++k) ekf.predict({-1.0, 0.0}, 0.05);
  std::vector<Observation> scan;
  for (std::int64_t i = 0; i < landmarks; ++i) {
    scan.push_back(observation_of(i, landmarks));
    if (scan.size() == 10 || i + 1 == landmarks) {
      ekf.observe(scan);
      scan.clear();
    }
  }
  return ekf;
}

// Arg: N. One single-observation scan per iteration, cycling through the landmarks.
void observe_benchmark(benchmark::State& state, Association association) {
  const std::int64_t n = state.range(0);
  EkfSlam ekf = make_map(association, n);
  if (ekf.landmark_count() != static_cast<std::size_t>(n)) {
    state.SkipWithError("the map was not built as intended");
    return;
  }
  std::int64_t i = 0;
  Observation scan[1];
  for (auto _ : state) {
    scan[0] = observation_of(i, n);
    ekf.observe(scan);
    i = i + 1 == n ? 0 : i + 1;
  }
  if (ekf.landmark_count() != static_cast<std::size_t>(n)) {
    state.SkipWithError("an observation started a new landmark");
  }
  state.counters["state_dim"] = static_cast<double>(3 + 2 * n);
  state.counters["covariance_MB"] = 8.0 * std::pow(3.0 + 2.0 * static_cast<double>(n), 2) / 1e6;
}

void BM_EkfSlamObserveKnown(benchmark::State& state) {
  observe_benchmark(state, Association::kKnown);
}
void BM_EkfSlamObserveMl(benchmark::State& state) {
  observe_benchmark(state, Association::kMaximumLikelihood);
}

void BM_EkfSlamPredict(benchmark::State& state) {
  EkfSlam ekf = make_map(Association::kKnown, state.range(0));
  for (auto _ : state) ekf.predict({1.0, 0.01}, 0.001);
}

void sizes(benchmark::internal::Benchmark* b) {
  for (const std::int64_t n : {10, 100, 1000, 2000}) {
    if (n <= fastslam::bench::upto(2000, 10)) b->Arg(n);
  }
}

BENCHMARK(BM_EkfSlamObserveKnown)->ArgName("N")->Apply(sizes)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_EkfSlamObserveMl)->ArgName("N")->Apply(sizes)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_EkfSlamPredict)->ArgName("N")->Apply(sizes)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace fastslam::engine
