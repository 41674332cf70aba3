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
//
// BM_AssociationKernel/K: the association kernel alone, one particle, FastSLAM 1.0, maximum
// likelihood: the candidate search of a scan of 8 observations (engine/internal/
// candidate_search.h: the disc query of the particle's spatial index, the extent and
// Mahalanobis bounds, each candidate's bound on ln p) and the joint choice, which evaluates the
// candidates it needs exactly (choose_maximum_likelihood), with about K = 10, 100, 1000
// landmarks inside each observation's search disc (a dense patch around each observed
// landmark, in a 10^4-landmark map). The time is per particle-observation (a call's time / 8);
// `in_disc`: landmarks inside the disc per observation; `evaluated`: candidates evaluated
// exactly and kept (within the gate and above ln p0), per observation;
// tools/scripts/callgrind_kernels.sh counts its instructions (association_kernel, not inlined)
// against the floor (landmark_ekf_benchmark.cc).
//
// BM_AssociationKernelInRange/K: the same kernel where K = 10, 100, 1000 landmarks lie in the
// sensor's range (30 m, +-90 degrees), each seen about ten times, 8 of them observed with the
// sensor's noise: the map's density a user's sensor sees, where the discs hold a few landmarks
// and most are dropped by their own reach and the Mahalanobis bound.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <span>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench/bench_util.h"
#include "engine/association.h"
#include "engine/filter_config.h"
#include "engine/internal/candidate_search.h"
#include "engine/internal/map_update.h"
#include "engine/landmark_ekf.h"
#include "engine/measurement_model.h"
#include "memory/landmark_tree.h"
#include "memory/node_heap.h"
#include "memory/spatial_index.h"
#include "tools/studies/scaling_study.h"

namespace fastslam::engine {
namespace bench {

// One particle's association of one scan: candidates, then the maximum-likelihood choice.
// Returns the log weight factor. Not inlined, so that callgrind counts it by name
// (fastslam::engine::bench::association_kernel).
[[gnu::noinline]] double association_kernel(
    const internal::SearchInput& in, const PoseGaussian<3>& prior, const memory::LandmarkTree& map,
    const memory::SpatialIndex& index, const std::vector<internal::PlannedObservation>& scan,
    internal::CandidateScratch& scratch, std::span<std::int64_t> assignment) {
  internal::find_candidates<3, false, true>(in, prior, map, index, scan, scratch);
  return internal::choose_maximum_likelihood<3>(in, prior, map, scan, scratch, in.log_p0,
                                                assignment);
}

}  // namespace bench

namespace {

// What both kernel worlds share: one particle at the origin heading along x, its map and index,
// the filter's default noises, gate, search scale and p0, and a scan of 8 observations.
struct KernelMap {
  static constexpr std::size_t kObservations = 8;
  memory::PoolHeap heap;
  memory::LandmarkTree map{heap};
  memory::SpatialIndex index{heap};
  RangeBearingModel sensor;
  internal::SearchInput in;
  PoseGaussian<3> prior;
  std::vector<internal::PlannedObservation> scan;
  std::mt19937_64 rng{7};
  std::uniform_real_distribution<double> unit{0.0, 1.0};

  KernelMap() {
    const FilterConfig config;
    in.sensor = &sensor;
    in.r << config.sensor.sigma_range * config.sensor.sigma_range, 0.0, 0.0,
        config.sensor.sigma_bearing * config.sensor.sigma_bearing;
    in.gate = config.gating.gate;
    in.search_scale = config.gating.search_scale;
    in.log_p0 = config.log_new_landmark;
    prior.mean.setZero();
  }
  double radius_of(std::size_t j) const {
    return std::sqrt(in.search_scale * in.search_scale * in.gate *
                     (in.variance_bound + internal::measurement_variance(in.r, scan[j].z[0])));
  }
  void add(const LandmarkGaussian& g) {
    memory::Landmark l;
    store_gaussian(g, l);
    l.log_odds = 1.0;
    l.id = map.size();
    const memory::Slot slot = map.insert(l);
    index.insert(slot, l.x, l.y, internal::largest_variance(l));
  }
  // A grid of 10^4 landmarks 10 m apart with covariance `cov`, none within `clear` of the origin
  // or within two disc radii of `observed` (so the index has the depth of a large map).
  void background(const Eigen::Matrix2d& cov, double clear,
                  const std::vector<LandmarkGaussian>& observed) {
    for (int gx = -50; gx < 50; ++gx) {
      for (int gy = -50; gy < 50; ++gy) {
        LandmarkGaussian g;
        g.cov = cov;
        g.mean = {10.0 * gx + 5.0 * unit(rng), 10.0 * gy + 5.0 * unit(rng)};
        bool free = g.mean.norm() > clear;
        for (std::size_t j = 0; j < observed.size(); ++j) {
          free = free && (g.mean - observed[j].mean).norm() > 2.0 * radius_of(j);
        }
        if (free) add(g);
      }
    }
  }
  // Landmarks inside the observations' search discs, per observation (brute force).
  double in_disc() const {
    const Pose pose = prior.mean;
    std::size_t inside = 0;
    for (std::size_t j = 0; j < scan.size(); ++j) {
      const Eigen::Vector2d at = sensor.landmark_from(scan[j].z, pose);
      const double r = radius_of(j);
      for (const auto [slot, l] : map) inside += (Eigen::Vector2d(l.x, l.y) - at).norm() <= r;
    }
    return static_cast<double>(inside) / static_cast<double>(scan.size());
  }
};

// The dense world (BM_AssociationKernel): 8 observations of landmarks at 6 .. 27 m within +-60
// degrees, each landmark with `per_disc` - 1 others spread uniformly over its observation's
// search disc (each with the covariance a first sighting from there gives, so that its own
// reach covers the disc too), and the background grid.
struct KernelWorld : KernelMap {
  explicit KernelWorld(std::size_t per_disc) {
    const Pose pose = prior.mean;
    std::vector<LandmarkGaussian> observed;
    for (std::size_t j = 0; j < kObservations; ++j) {
      const double range = 6.0 + 3.0 * static_cast<double>(j);
      const double bearing = (unit(rng) - 0.5) * 2.0 * std::numbers::pi / 3.0;
      internal::PlannedObservation o;
      o.z = {range, bearing};
      scan.push_back(o);
      observed.push_back(initialize_landmark(sensor, pose, o.z, in.r));
      in.variance_bound = std::max(in.variance_bound, internal::measurement_variance(in.r, range));
    }
    for (std::size_t j = 0; j < kObservations; ++j) {
      add(observed[j]);
      const double r = radius_of(j);
      for (std::size_t k = 1; k < per_disc; ++k) {
        const double a = 2.0 * std::numbers::pi * unit(rng);
        const double d = r * std::sqrt(unit(rng));
        LandmarkGaussian g = observed[j];
        g.mean += Eigen::Vector2d(d * std::cos(a), d * std::sin(a));
        add(g);
      }
    }
    background(observed[0].cov, 0.0, observed);
  }
};

// The sensor's view (BM_AssociationKernelInRange): `in_range` landmarks spread uniformly over
// the field of view (range 1 .. 30 m, +-90 degrees), each with a tenth of the covariance its
// first sighting from the origin gives (a landmark seen about ten times), 8 of them observed
// with the sensor's noise, and the background grid beyond 40 m. The search's variance bound is
// the filter's after scans out to 30 m.
struct InRangeWorld : KernelMap {
  explicit InRangeWorld(std::size_t in_range) {
    const Pose pose = prior.mean;
    constexpr double kMaxRange = 30.0;
    in.variance_bound = internal::measurement_variance(in.r, kMaxRange);
    std::normal_distribution<double> normal;
    std::vector<LandmarkGaussian> observed;
    for (std::size_t k = 0; k < in_range; ++k) {
      const double range = std::max(1.0, kMaxRange * std::sqrt(unit(rng)));
      const double bearing = (unit(rng) - 0.5) * std::numbers::pi;
      LandmarkGaussian g = initialize_landmark(sensor, pose, Eigen::Vector2d(range, bearing), in.r);
      g.cov *= 0.1;
      add(g);
      if (k < kObservations) {
        internal::PlannedObservation o;
        o.z = sensor.predict(g.mean, pose) + Eigen::Vector2d(std::sqrt(in.r(0, 0)) * normal(rng),
                                                             std::sqrt(in.r(1, 1)) * normal(rng));
        scan.push_back(o);
        observed.push_back(g);
      }
    }
    background(observed[0].cov, kMaxRange + 10.0, {});
  }
};

// One call's time, reported per particle-observation (the clock reads add ~1%), with the
// world's counters.
void time_kernel(benchmark::State& state, KernelMap& w) {
  std::vector<Eigen::Vector2d> bearings;  // per scan, as the filter's pass gives them
  internal::scan_bearings(w.scan, bearings);
  w.in.bearings = bearings;
  internal::CandidateScratch scratch;
  std::vector<std::int64_t> assignment(w.scan.size());
  const auto observations = static_cast<double>(w.scan.size());
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    benchmark::DoNotOptimize(
        bench::association_kernel(w.in, w.prior, w.map, w.index, w.scan, scratch, assignment));
    const auto t1 = std::chrono::steady_clock::now();
    state.SetIterationTime(std::chrono::duration<double>(t1 - t0).count() / observations);
  }
  state.counters["observations"] = observations;
  state.counters["in_disc"] = w.in_disc();
  state.counters["evaluated"] = static_cast<double>(scratch.terms.size()) / observations;
  state.counters["associated"] = static_cast<double>(std::count_if(
      assignment.begin(), assignment.end(), [](std::int64_t a) { return a != kNewLandmark; }));
}

void BM_AssociationKernel(benchmark::State& state) {
  KernelWorld w(static_cast<std::size_t>(state.range(0)));
  time_kernel(state, w);
}

BENCHMARK(BM_AssociationKernel)
    ->ArgName("in_disc")
    ->Arg(10)
    ->Arg(100)
    ->Arg(1000)
    ->UseManualTime()
    ->Unit(benchmark::kNanosecond);

void BM_AssociationKernelInRange(benchmark::State& state) {
  InRangeWorld w(static_cast<std::size_t>(state.range(0)));
  time_kernel(state, w);
}

BENCHMARK(BM_AssociationKernelInRange)
    ->ArgName("in_range")
    ->Arg(10)
    ->Arg(100)
    ->Arg(1000)
    ->UseManualTime()
    ->Unit(benchmark::kNanosecond);

// One point of the scaling study (tools/studies/scaling_study.h), which owns the setup and the
// timing.
void BM_AssociationScaling(benchmark::State& state) {
  tools::ScalingOptions options;
  options.updates = static_cast<std::uint64_t>(fastslam::bench::upto(500, 60));
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
  const std::int64_t max_n = fastslam::bench::upto(1'000'000, 1'000);
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
