// The scaling studies (paper section 8, fig. 14-15): the time of a sensor update and the live
// memory of M particles whose maps hold N landmarks at constant density, for every N x M x
// threads of the lists, on the tree engine or the linear-copy baseline (linear_baseline.h).
// One point: a grid world of N landmarks, `updates` scans simulated along the start of its
// route, every particle sharing the true map as a prior (Filter::set_map); timed: feeding the
// controls and scans. docs/scaling.md has the set-up in full and the results.
//
// Ownership: plain values. Thread safety: one study per call; the filter runs its own threads.
// Costs: O(N log N) setup per point (world, kd-tree, map), then the updates; the linear engine
// is O(M N) per update and refuses N above `linear_max_landmarks`.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "engine/filter_config.h"
#include "parallel/collective.h"

namespace fastslam::tools {

enum class ScalingEngine : std::uint8_t { kTree, kLinear };
std::string_view to_string(ScalingEngine engine);

struct ScalingOptions {
  ScalingEngine engine = ScalingEngine::kTree;
  std::uint64_t linear_max_landmarks = 100'000;  // kLinear refuses larger N
  std::vector<std::uint64_t> landmarks = {1'000, 1'000'000};
  // run_scaling_command runs every (N, M, threads) of these lists, N outermost, threads
  // innermost, setting filter.particles and filter.threads per point; run_scaling_point uses
  // filter.particles and filter.threads as they are.
  std::vector<unsigned> particles = {100};
  std::vector<unsigned> threads = {1};
  std::uint64_t updates = 500;  // scans timed per point
  std::uint64_t repeats = 1;    // runs per point; the fastest is reported (a shared machine only
                                // ever adds time), every run's time is kept
  double spacing = 10.0;        // m per landmark
  engine::FilterConfig filter;  // algorithm, association, seed, ... (particles, threads: above)
  // The ranks sharing each point's particle set (`fastslam bench scaling` under mpirun; every
  // rank runs the study; rank 0 reports). Null: one process.
  std::shared_ptr<parallel::Collective> group;
};

struct ScalingPoint {
  std::uint64_t landmarks = 0;
  unsigned particles = 0;
  unsigned threads = 0;  // used (the linear baseline: 1)
  std::uint64_t updates = 0;
  std::uint64_t observations = 0;
  double seconds = 0.0;  // all updates, wall
  double seconds_per_update = 0.0;
  double cpu_seconds = 0.0;  // CPU time of the process (all threads) over the same updates
  std::int64_t live_bytes = 0;
  std::int64_t lower_bound_bytes = 0;  // one map
  double pose_error = 0.0;  // m, weighted mean position against the truth after the last update
  // Thread-seconds per phase (FilterStatistics): resample includes releasing the replaced
  // particles' paths (the resampler drops their roots), predict only the controls run
  // outside a scan's pass (the rest is fused into the pass and counted under associate/update).
  double predict_seconds = 0.0, associate_seconds = 0.0, update_seconds = 0.0,
         resample_seconds = 0.0;
  double observe_wall_seconds = 0.0;  // wall time inside observe (tree engine; linear: 0)
  std::vector<double> run_seconds;    // every repeat's `seconds` (run_scaling_command)
  // Over ranks (ScalingOptions::group; rank 0's times): wall seconds in the set's reductions
  // (all_gather: weights, best particle, trajectory) and in the exchange's transfer (waiting
  // for the slowest rank included), and in the whole exchange (packing, transfer, unpacking
  // and the indices' rebuild); the resamplings; every rank's bytes sent in them, and what
  // sending each copy with its whole map would have cost.
  int ranks = 1;
  double gather_seconds = 0.0, transfer_seconds = 0.0, exchange_seconds = 0.0;
  std::uint64_t resamples = 0, exchange_bytes = 0, exchange_naive_bytes = 0, exchange_copies = 0;
};

// The transport's costs between the group's ranks (each rank sending one message of s bytes to
// every other at once, as the resampling exchange does): the median wall time of an exchange,
// modelled as latency + s * seconds_per_byte: the latency that of 1 B, the per-byte cost that
// of 4 MiB beyond it; the samples from 1 B to 4 MiB are kept.
struct TransportCost {
  double latency_seconds = 0.0;
  double seconds_per_byte = 0.0;
  std::vector<std::pair<std::uint64_t, double>> samples;  // (bytes, median seconds)
};
TransportCost measure_transport(parallel::Collective& group);

// Throws std::invalid_argument for N = 0, zero updates, an invalid filter config, or (kLinear)
// N above linear_max_landmarks or a config the baseline does not support.
ScalingPoint run_scaling_point(const ScalingOptions& options, std::uint64_t landmarks);

// Every (N, M, threads) of the options in turn, each `repeats` times (the fastest reported):
// prints a table to stdout and, if not empty, writes `json_path` ({"config": ...,
// "points": [{landmarks, particles, threads, seconds_per_update, live_bytes,
// lower_bound_bytes, ...}]}) and `csv_path` (a header line, then one line per point with the
// same scalar fields). Checks every N and the lists against the engine's limits before running
// any (throws std::invalid_argument). Returns the process exit code.
int run_scaling_command(const ScalingOptions& options, const std::string& json_path,
                        const std::string& csv_path = "");

}  // namespace fastslam::tools
