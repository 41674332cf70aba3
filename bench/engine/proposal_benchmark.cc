// ns per FastSLAM 2.0 proposal step: fold one observation into the Gaussian pose proposal
// (eq. 42, 48-49 in Kalman form, with its eq. 60-61 weight term), a whole scan of k folds, and
// one pose draw.
#include <benchmark/benchmark.h>

#include "bench/bench_util.h"
#include "bench/engine/bench_inputs.h"
#include "engine/proposal.h"

namespace fastslam::engine::bench {
namespace {

void BM_ProposalFold(benchmark::State& state) {
  const RangeBearingModel model;
  const auto scenarios = make_scenarios(model);
  const Eigen::Matrix2d r = bailey_r();
  std::size_t i = 0;
  for (auto _ : state) {
    const Scenario& s = scenarios[i++ & (kRing - 1)];
    double log_lik = 0.0;
    benchmark::DoNotOptimize(fold_observation<3>(model, s.motion, s.lm, s.z, r, &log_lik));
    benchmark::DoNotOptimize(log_lik);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_ProposalFold);

// A scan of k observations folded in turn (each linearised at the refined mean).
void BM_ProposalScan(benchmark::State& state) {
  const RangeBearingModel model;
  const auto scenarios = make_scenarios(model);
  const Eigen::Matrix2d r = bailey_r();
  const auto k = static_cast<std::size_t>(state.range(0));
  std::size_t i = 0;
  for (auto _ : state) {
    PoseGaussian<3> proposal = scenarios[i & (kRing - 1)].motion;
    double log_w = 0.0;
    for (std::size_t j = 0; j < k; ++j) {
      const Scenario& s = scenarios[(i + j) & (kRing - 1)];
      double term = 0.0;
      proposal = fold_observation<3>(model, proposal, s.lm, s.z, r, &term);
      log_w += term;
    }
    ++i;
    benchmark::DoNotOptimize(proposal);
    benchmark::DoNotOptimize(log_w);
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(k));
}
BENCHMARK(BM_ProposalScan)
    ->ArgName("observations")
    ->RangeMultiplier(2)
    ->Range(1, fastslam::bench::upto(16, 2));

void BM_ProposalSample(benchmark::State& state) {
  const RangeBearingModel model;
  const auto scenarios = make_scenarios(model);
  const double normals[3] = {0.3, -1.2, 0.7};
  std::size_t i = 0;
  for (auto _ : state) {
    const Scenario& s = scenarios[i++ & (kRing - 1)];
    benchmark::DoNotOptimize(sample_pose<3>(s.motion, normals));
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_ProposalSample);

}  // namespace
}  // namespace fastslam::engine::bench
