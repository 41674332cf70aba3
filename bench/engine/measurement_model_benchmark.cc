// ns per call of the range-bearing model (one sqrt, one atan2; sin/cos with a sensor offset).
#include <benchmark/benchmark.h>

#include "bench/engine/bench_inputs.h"
#include "engine/measurement_model.h"

namespace fastslam::engine::bench {
namespace {

void BM_MeasurementPredict(benchmark::State& state) {
  const RangeBearingModel model(SensorOffset{state.range(0) != 0 ? 3.78 : 0.0, 0.0, 0.0});
  const auto scenarios = make_scenarios(model);
  std::size_t i = 0;
  for (auto _ : state) {
    const Scenario& s = scenarios[i++ & (kRing - 1)];
    benchmark::DoNotOptimize(model.predict(s.lm.mean, s.pose));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_MeasurementPredict)->ArgName("offset")->Arg(0)->Arg(1);

void BM_MeasurementLinearize(benchmark::State& state) {
  const RangeBearingModel model(SensorOffset{state.range(0) != 0 ? 3.78 : 0.0, 0.0, 0.0});
  const auto scenarios = make_scenarios(model);
  std::size_t i = 0;
  for (auto _ : state) {
    const Scenario& s = scenarios[i++ & (kRing - 1)];
    benchmark::DoNotOptimize(model.linearize(s.lm.mean, s.pose));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_MeasurementLinearize)->ArgName("offset")->Arg(0)->Arg(1);

}  // namespace
}  // namespace fastslam::engine::bench
