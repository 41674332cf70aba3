// ns per motion-model call: the FastSLAM 1.0 pose draw (sample) and the FastSLAM 2.0 prior
// (predict + P = V M V^T) for the car models.
#include <benchmark/benchmark.h>

#include "bench/engine/bench_inputs.h"
#include "engine/motion_model.h"

namespace fastslam::engine::bench {
namespace {

template <class Model>
void BM_MotionSample(benchmark::State& state) {
  const BenchMotion<Model> motion;
  const Model& model = motion;
  const auto scenarios = make_scenarios(RangeBearingModel());
  const Eigen::Vector2d u(3.0, 0.1);
  const Eigen::Vector2d sigmas(0.3, 0.05);
  const double normals[2] = {0.4, -0.8};
  std::size_t i = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(
        model.sample(scenarios[i++ & (kRing - 1)].pose, u, 0.025, sigmas, normals));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_MotionSample<BaileyCarModel>);
BENCHMARK(BM_MotionSample<AckermannModel>);

template <class Model>
void BM_MotionPrior(benchmark::State& state) {
  const BenchMotion<Model> motion;
  const Model& model = motion;
  const auto scenarios = make_scenarios(RangeBearingModel());
  const Eigen::Vector2d u(3.0, 0.1);
  const Eigen::Matrix2d m = Model::control_covariance({0.3, 0.05});
  std::size_t i = 0;
  for (auto _ : state) {
    const Pose& s = scenarios[i++ & (kRing - 1)].pose;
    benchmark::DoNotOptimize(model.predict(s, u, 0.025));
    benchmark::DoNotOptimize(model.pose_noise(s, u, 0.025, m));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_MotionPrior<BaileyCarModel>);
BENCHMARK(BM_MotionPrior<AckermannModel>);

}  // namespace
}  // namespace fastslam::engine::bench
