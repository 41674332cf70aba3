// ns per FastSLAM 1.0 landmark step: linearise, Q, likelihood (eq. 31-32) and, for the update,
// the Joseph-form EKF update (eq. 25). The design's budget calls this "the bare 2x2 EKF
// arithmetic, about 40 ns".
#include <benchmark/benchmark.h>

#include "bench/engine/bench_inputs.h"
#include "engine/landmark_ekf.h"

namespace fastslam::engine::bench {
namespace {

// One FS1 landmark update plus its log-likelihood, from a fresh prior each time.
void BM_LandmarkEkfUpdate(benchmark::State& state) {
  const RangeBearingModel model;
  const auto scenarios = make_scenarios(model);
  const Eigen::Matrix2d r = bailey_r();
  std::size_t i = 0;
  for (auto _ : state) {
    const Scenario& s = scenarios[i++ & (kRing - 1)];
    LandmarkGaussian lm = s.lm;
    benchmark::DoNotOptimize(update_landmark(model, lm, s.pose, s.z, r));
    benchmark::DoNotOptimize(lm);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_LandmarkEkfUpdate);

// Scoring one data-association candidate: the terms without the update.
void BM_LandmarkEkfEvaluate(benchmark::State& state) {
  const RangeBearingModel model;
  const auto scenarios = make_scenarios(model);
  const Eigen::Matrix2d r = bailey_r();
  std::size_t i = 0;
  for (auto _ : state) {
    const Scenario& s = scenarios[i++ & (kRing - 1)];
    benchmark::DoNotOptimize(evaluate_observation(model, s.lm, s.pose, s.z, r).log_likelihood);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_LandmarkEkfEvaluate);

// The update alone, given the evaluated terms (what the filter pays after choosing).
void BM_LandmarkEkfApply(benchmark::State& state) {
  const RangeBearingModel model;
  const auto scenarios = make_scenarios(model);
  const Eigen::Matrix2d r = bailey_r();
  std::array<LandmarkObservation, kRing> observations;
  for (std::size_t k = 0; k < kRing; ++k) {
    observations[k] =
        evaluate_observation(model, scenarios[k].lm, scenarios[k].pose, scenarios[k].z, r);
  }
  std::size_t i = 0;
  for (auto _ : state) {
    const std::size_t k = i++ & (kRing - 1);
    LandmarkGaussian lm = scenarios[k].lm;
    apply_update(lm, observations[k], r);
    benchmark::DoNotOptimize(lm);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_LandmarkEkfApply);

}  // namespace
}  // namespace fastslam::engine::bench
