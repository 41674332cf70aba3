// ns per particle and control step of the vectorised control loop (engine/motion_batch.h): the
// FastSLAM 1.0 pose draw (sample_block, normals given) and the FastSLAM 2.0 prior
// (predict_block: mean and covariance), over a block of `lanes` particles carried through
// `steps` controls per call (the filter's shape: one block, every control between two scans),
// against the scalar model per particle and step. Items = particle steps. Every iteration
// starts from the same states (a copy of N x lanes doubles, included), so that random walks
// (the Brownian model's velocities) cannot drift out of the vector path's domain.
#include <algorithm>
#include <cstddef>
#include <random>
#include <type_traits>
#include <vector>

#include <benchmark/benchmark.h>

#include "engine/motion_batch.h"
#include "engine/motion_model.h"

namespace fastslam::engine {
namespace {

// The model: its default, and for the Ackermann car the Victoria Park car's geometry.
template <class Model>
struct BenchMotion : Model {};
template <>
struct BenchMotion<AckermannModel> : AckermannModel {
  BenchMotion() : AckermannModel(AckermannGeometry{3.78, 0.50, 2.83, 0.76}) {}
};

template <class Model>
struct Inputs {
  static constexpr int N = Model::kStateDim;
  std::vector<double> columns;
  std::vector<double> initial;
  std::vector<double> cov;
  std::vector<double> normals;
  std::vector<ControlStep> steps;
  StateBlock<N> block;
  CovBlock<N> cov_block{};

  Inputs(std::size_t lanes, std::size_t k)
      : columns(N * lanes), cov(kCovEntries<N> * lanes), normals(2 * k * lanes) {
    std::mt19937_64 rng(1);
    std::uniform_real_distribution<double> pos(-100, 100), heading(-3.1, 3.1);
    std::normal_distribution<double> gauss;
    for (std::size_t l = 0; l < lanes; ++l) {
      columns[l] = pos(rng);
      columns[lanes + l] = pos(rng);
      columns[2 * lanes + l] = heading(rng);
      if (N == 5) columns[3 * lanes + l] = 3.0;  // Brownian: speed in the state
      // The curvature walk: a 20 m radius (the omega walk's turn rate stays 0, as before).
      if constexpr (std::is_same_v<Model, BrownianCurvatureModel>) columns[4 * lanes + l] = 0.05;
    }
    for (double& n : normals) n = gauss(rng);
    // The Brownian model's control is the velocity increment, zero in the filter.
    const bool brownian = N == 5;
    for (std::size_t s = 0; s < k; ++s) {
      steps.push_back({brownian ? 0.0 : 3.0, brownian ? 0.0 : 0.1 * gauss(rng), 0.025});
    }
    initial = columns;
    block.lanes = lanes;
    for (int c = 0; c < N; ++c) block.col[c] = columns.data() + c * lanes;
    for (int e = 0; e < kCovEntries<N>; ++e) cov_block[e] = cov.data() + e * lanes;
  }
};

// Args: lanes, steps per call.
template <class Model>
void BM_MotionBatchSample(benchmark::State& state) {
  const auto lanes = static_cast<std::size_t>(state.range(0));
  const auto k = static_cast<std::size_t>(state.range(1));
  Inputs<Model> in(lanes, k);
  const BenchMotion<Model> motion;
  const Model& model = motion;
  const Eigen::Vector2d sigmas(0.3, 0.05);
  for (auto _ : state) {
    std::copy(in.initial.begin(), in.initial.end(), in.columns.begin());
    sample_block(model, in.block, in.steps, sigmas, in.normals.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(lanes * k));
}

template <class Model>
void BM_MotionBatchPredict(benchmark::State& state) {
  const auto lanes = static_cast<std::size_t>(state.range(0));
  const auto k = static_cast<std::size_t>(state.range(1));
  Inputs<Model> in(lanes, k);
  const BenchMotion<Model> motion;
  const Model& model = motion;
  const Eigen::Vector2d sigmas(0.3, 0.05);
  for (auto _ : state) {
    std::copy(in.initial.begin(), in.initial.end(), in.columns.begin());
    predict_block(model, in.block, in.steps, sigmas, in.cov_block);
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(lanes * k));
}

// The scalar oracle the batch replaces: sample per particle and step.
template <class Model>
void BM_MotionScalarSample(benchmark::State& state) {
  const auto lanes = static_cast<std::size_t>(state.range(0));
  const auto k = static_cast<std::size_t>(state.range(1));
  Inputs<Model> in(lanes, k);
  const BenchMotion<Model> motion;
  const Model& model = motion;
  const Eigen::Vector2d sigmas(0.3, 0.05);
  for (auto _ : state) {
    std::copy(in.initial.begin(), in.initial.end(), in.columns.begin());
    for (std::size_t s = 0; s < k; ++s) {
      const Eigen::Vector2d u(in.steps[s].u0, in.steps[s].u1);
      for (std::size_t l = 0; l < lanes; ++l) {
        typename Model::State st;
        for (int c = 0; c < Model::kStateDim; ++c) st[c] = in.block.col[c][l];
        const double n[2] = {in.normals[2 * s * lanes + l], in.normals[(2 * s + 1) * lanes + l]};
        st = model.sample(st, u, in.steps[s].dt, sigmas, n);
        for (int c = 0; c < Model::kStateDim; ++c) in.block.col[c][l] = st[c];
      }
    }
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(lanes * k));
}

void shapes(benchmark::internal::Benchmark* b) {
  b->ArgNames({"lanes", "steps"});
  b->Args({16, 9})->Args({56, 9})->Args({512, 9});
}

BENCHMARK(BM_MotionBatchSample<BaileyCarModel>)->Apply(shapes);
BENCHMARK(BM_MotionBatchSample<AckermannModel>)->Apply(shapes);
BENCHMARK(BM_MotionBatchSample<BrownianVelocityModel>)->Apply(shapes);
BENCHMARK(BM_MotionBatchSample<BrownianCurvatureModel>)->Apply(shapes);
BENCHMARK(BM_MotionBatchPredict<BaileyCarModel>)->Apply(shapes);
BENCHMARK(BM_MotionBatchPredict<BrownianVelocityModel>)->Apply(shapes);
BENCHMARK(BM_MotionBatchPredict<BrownianCurvatureModel>)->Apply(shapes);
BENCHMARK(BM_MotionScalarSample<BaileyCarModel>)->Apply(shapes);

}  // namespace
}  // namespace fastslam::engine
