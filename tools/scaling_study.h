// The scaling study in N (paper section 8, fig. 14-15): the time of a sensor update and the live
// memory of M particles whose maps hold N landmarks at constant density, for N over several
// decades. `fastslam bench scaling` runs it from the command line; the association benchmark
// (bench/engine/association_benchmark.cc) runs one point of it under Google Benchmark.
//
// One point: a grid world of N landmarks (one per spacing x spacing cell) and its lawnmower
// route; `updates` scans simulated along the start of the route (the vehicle sees the same
// density whatever N is); a filter whose particles all share the true map as a prior
// (Filter::set_map: covariance 0.1 m^2 per axis, existence log-odds 50, ids = world indices so
// known association works too). Timed: feeding the controls and scans (every particle phase
// and the resampling). Memory: the heap's live bytes at the end, and a lower bound, the live
// bytes of the one shared map right after set_map (every particle needs at least that).
//
// Engines: `kTree` is the filter (engine/filter.h); `kLinear` the linear-copy baseline
// (tools/linear_baseline.h: flat per-particle maps copied whole at resampling, FastSLAM 1.0 with
// ML only, resampling every scan), given the same prior map as flat copies; its live bytes are
// the sum of the maps' capacities and its lower bound one flat map (N * 64 bytes). It is O(M N)
// per update, so it refuses N above `linear_max_landmarks`.
//
// Ownership: plain values. Thread safety: one study per call; the filter runs its own threads.
// Costs: O(N log N) setup per point (world, kd-tree, map), then the updates.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "engine/filter_config.h"

namespace fastslam::tools {

enum class ScalingEngine : std::uint8_t { kTree, kLinear };
std::string_view to_string(ScalingEngine engine);

struct ScalingOptions {
  ScalingEngine engine = ScalingEngine::kTree;
  std::uint64_t linear_max_landmarks = 100'000;  // kLinear refuses larger N
  std::vector<std::uint64_t> landmarks = {1'000, 1'000'000};
  std::uint64_t updates = 500;  // scans timed per point
  double spacing = 10.0;        // m per landmark
  engine::FilterConfig filter;  // algorithm, particles, association, threads, seed, ...
};

struct ScalingPoint {
  std::uint64_t landmarks = 0;
  std::uint64_t updates = 0;
  std::uint64_t observations = 0;
  double seconds = 0.0;  // all updates, wall
  double seconds_per_update = 0.0;
  std::int64_t live_bytes = 0;
  std::int64_t lower_bound_bytes = 0;  // one map
  double pose_error = 0.0;  // m, weighted mean position against the truth after the last update
  double predict_seconds = 0.0, associate_seconds = 0.0, update_seconds = 0.0,
         resample_seconds = 0.0;  // thread-seconds per phase (FilterStatistics)
};

// Throws std::invalid_argument for N = 0, zero updates, an invalid filter config, or (kLinear)
// N above linear_max_landmarks or a config the baseline does not support.
ScalingPoint run_scaling_point(const ScalingOptions& options, std::uint64_t landmarks);

// Every N of the options in turn: prints a table to stdout and, if `json_path` is not empty,
// writes {"config": ..., "points": [{landmarks, seconds_per_update, live_bytes,
// lower_bound_bytes, ...}]} there. Checks every N against the engine's limits before running
// any (throws std::invalid_argument). Returns the process exit code.
int run_scaling_command(const ScalingOptions& options, const std::string& json_path);

}  // namespace fastslam::tools
