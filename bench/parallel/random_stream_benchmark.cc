// Throughput of the random streams: scalar draws, the batch functions over a block of particles
// (swept over the block size, as the particle kernel calls them) and the stream fills.
// Items are values (normals or uniforms); google-benchmark reports them per second.
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench/bench_util.h"
#include "parallel/random_stream.h"

namespace fastslam::parallel {
namespace {

constexpr std::uint64_t kSeed = 0x5EED5EED12345678u;

// normal() in a loop on one stream.
void BM_RandomStreamNormal(benchmark::State& state) {
  RandomStream stream({.seed = kSeed, .step = 1, .particle = 0, .purpose = Purpose::kMotion});
  const auto draws = static_cast<std::size_t>(state.range(0));
  for (auto _ : state) {
    double sum = 0.0;
    for (std::size_t i = 0; i < draws; ++i) sum += stream.normal();
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_RandomStreamNormal)->Arg(fastslam::bench::upto(1 << 16, 64));

// A fresh stream per particle, three normal() each: the engine's motion draws done the slow way.
void BM_RandomStreamNormalPerParticle(benchmark::State& state) {
  const auto particles = static_cast<std::uint32_t>(state.range(0));
  std::vector<double> out(std::size_t{particles} * 3);
  std::uint64_t step = 0;
  for (auto _ : state) {
    ++step;
    for (std::uint32_t k = 0; k < particles; ++k) {
      RandomStream stream(
          {.seed = kSeed, .step = step, .particle = k, .purpose = Purpose::kMotion});
      for (int j = 0; j < 3; ++j) out[std::size_t{k} * 3 + j] = stream.normal();
    }
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * state.range(0) * 3);
}
BENCHMARK(BM_RandomStreamNormalPerParticle)->Arg(fastslam::bench::upto(1 << 16, 64));

// normals_for_particles over 2^16 particles (2^6 under smoke), `per_particle` normals each,
// in calls of `block` particles. Args: block, per_particle.
void BM_RandomStreamNormalsForParticles(benchmark::State& state) {
  const auto block = static_cast<std::size_t>(state.range(0));
  const auto per_particle = static_cast<std::size_t>(state.range(1));
  const auto particles = static_cast<std::size_t>(fastslam::bench::upto(1 << 16, 64));
  std::vector<double> out(particles * per_particle);
  std::uint64_t step = 0;
  for (auto _ : state) {
    ++step;
    for (std::size_t first = 0; first < particles; first += block) {
      const std::size_t count = first + block <= particles ? block : particles - first;
      normals_for_particles(kSeed, step, Purpose::kMotion, static_cast<std::uint32_t>(first), count,
                            per_particle,
                            std::span(out).subspan(first * per_particle, count * per_particle));
    }
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(out.size()));
}
BENCHMARK(BM_RandomStreamNormalsForParticles)
    ->ArgNames({"block", "per_particle"})
    ->ArgsProduct({benchmark::CreateRange(1, fastslam::bench::upto(1 << 16, 64), 8), {3}})
    ->ArgsProduct({{1024}, {1, 2, 4, 16}});

// normal_pairs_for_particles over 2^16 particles (2^6 under smoke) in calls of `block`
// particles: the motion draws of FastSLAM 1.0 (two normals per particle and control, as two
// columns). Args: block.
void BM_RandomStreamNormalPairsForParticles(benchmark::State& state) {
  const auto block = static_cast<std::size_t>(state.range(0));
  const auto particles = static_cast<std::size_t>(fastslam::bench::upto(1 << 16, 64));
  std::vector<double> first_normals(particles);
  std::vector<double> second_normals(particles);
  std::uint64_t step = 0;
  for (auto _ : state) {
    ++step;
    for (std::size_t first = 0; first < particles; first += block) {
      const std::size_t count = first + block <= particles ? block : particles - first;
      normal_pairs_for_particles(kSeed, step, Purpose::kMotion, static_cast<std::uint32_t>(first),
                                 count, std::span(first_normals).subspan(first, count),
                                 std::span(second_normals).subspan(first, count));
    }
    benchmark::DoNotOptimize(first_normals.data());
    benchmark::DoNotOptimize(second_normals.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(2 * particles));
}
BENCHMARK(BM_RandomStreamNormalPairsForParticles)->ArgName("block")->Arg(16)->Arg(50)->Arg(1024);

// The filter's shape: one call per block of `block` particles covering 9 control steps (the
// webmap's controls per scan), the pairs of step j in columns j of stride `block`.
void BM_RandomStreamNormalPairsForSteps(benchmark::State& state) {
  const auto block = static_cast<std::size_t>(state.range(0));
  const auto particles = static_cast<std::size_t>(fastslam::bench::upto(1 << 16, 64));
  constexpr std::size_t kSteps = 9;
  std::vector<double> first_normals(kSteps * block);
  std::vector<double> second_normals(kSteps * block);
  std::vector<std::uint64_t> steps(kSteps);
  std::uint64_t step = 0;
  for (auto _ : state) {
    for (std::uint64_t& s : steps) s = ++step;
    for (std::size_t first = 0; first < particles; first += block) {
      normal_pairs_for_particles(kSeed, steps, Purpose::kMotion, static_cast<std::uint32_t>(first),
                                 block, first_normals, second_normals, block);
      benchmark::DoNotOptimize(first_normals.data());
      benchmark::DoNotOptimize(second_normals.data());
      benchmark::ClobberMemory();
    }
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(2 * kSteps * particles));
}
BENCHMARK(BM_RandomStreamNormalPairsForSteps)->ArgName("block")->Arg(16)->Arg(50)->Arg(1024);

// uniforms_for_particles, same shape (the resampler's draws).
void BM_RandomStreamUniformsForParticles(benchmark::State& state) {
  const auto block = static_cast<std::size_t>(state.range(0));
  const auto per_particle = static_cast<std::size_t>(state.range(1));
  const auto particles = static_cast<std::size_t>(fastslam::bench::upto(1 << 16, 64));
  std::vector<double> out(particles * per_particle);
  std::uint64_t step = 0;
  for (auto _ : state) {
    ++step;
    for (std::size_t first = 0; first < particles; first += block) {
      const std::size_t count = first + block <= particles ? block : particles - first;
      uniforms_for_particles(kSeed, step, Purpose::kResample, static_cast<std::uint32_t>(first),
                             count, per_particle,
                             std::span(out).subspan(first * per_particle, count * per_particle));
    }
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(out.size()));
}
BENCHMARK(BM_RandomStreamUniformsForParticles)
    ->ArgNames({"block", "per_particle"})
    ->ArgsProduct({{1, 1024}, {1, 4}});

// uniform() in a loop on one stream.
void BM_RandomStreamUniform(benchmark::State& state) {
  RandomStream stream({.seed = kSeed, .step = 1, .particle = 0, .purpose = Purpose::kResample});
  const auto draws = static_cast<std::size_t>(state.range(0));
  for (auto _ : state) {
    double sum = 0.0;
    for (std::size_t i = 0; i < draws; ++i) sum += stream.uniform();
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_RandomStreamUniform)->Arg(fastslam::bench::upto(1 << 16, 64));

// fill_normal / fill_uniform of `n` values from a fresh stream.
void BM_RandomStreamFillNormal(benchmark::State& state) {
  std::vector<double> out(static_cast<std::size_t>(state.range(0)));
  std::uint64_t step = 0;
  for (auto _ : state) {
    RandomStream stream({.seed = kSeed, .step = ++step, .particle = 0, .purpose = Purpose::kUser});
    stream.fill_normal(out);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_RandomStreamFillNormal)->Range(8, fastslam::bench::upto(1 << 16, 64));

void BM_RandomStreamFillUniform(benchmark::State& state) {
  std::vector<double> out(static_cast<std::size_t>(state.range(0)));
  std::uint64_t step = 0;
  for (auto _ : state) {
    RandomStream stream({.seed = kSeed, .step = ++step, .particle = 0, .purpose = Purpose::kUser});
    stream.fill_uniform(out);
    benchmark::DoNotOptimize(out.data());
    benchmark::ClobberMemory();
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_RandomStreamFillUniform)->Range(8, fastslam::bench::upto(1 << 16, 64));

}  // namespace
}  // namespace fastslam::parallel
