// What `fastslam run` reports once the events are done: the scores of the map against the true
// landmarks, metrics.json (docs/metrics.md has every key) and the summary printed to stdout,
// whose headline gives each error beside its dead-reckoning baseline and warns when the filter
// ended worse than that baseline.
//
// Ownership: plain values. Thread safety: pure functions. Costs: scoring the map is
// O(N log N) for N landmarks (tools/eval/map_metrics.h); the rest is O(1).
#pragma once

#include <cstdint>
#include <cstdio>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "engine/filter.h"
#include "engine/filter_config.h"
#include "tools/cli/run_command.h"
#include "tools/cli/run_recorder.h"
#include "tools/datasets/source.h"
#include "tools/eval/innovation_stats.h"
#include "tools/eval/landmark_provenance.h"
#include "tools/eval/latency_histogram.h"
#include "tools/eval/map_evaluation.h"
#include "tools/eval/map_metrics.h"

namespace fastslam::tools {

// The map against the true landmarks the run observed.
struct MapScores {
  MapScore paired;    // greedy pairs within the match radius (the RMSE's)
  double rmse = 0.0;  // known association: by id; else paired.rmse_m
  Gospa gospa;        // cutoff = the match radius, order 2, observed landmarks only
  // The same after the rigid motion that aligns the path with the truth: the map's shape
  // apart from its placement.
  std::optional<Gospa> gospa_aligned;
  double precision = 0.0;  // of the optimal matching within the match radius
  double recall = 0.0;
  std::size_t observed = 0;  // true landmarks observed
  // Unknown association (particle filters): what started each landmark of the map.
  std::optional<Provenance> provenance;
};

// Everything a run measured.
struct RunResult {
  engine::Estimate estimate;
  engine::FilterStatistics stats;
  RecordedRun trajectories;
  std::optional<MapScores> map;  // when the source has true landmarks
  double open_seconds = 0.0;     // opening the source: reading and parsing a recorded one
  // Its events after that (for a simulator: simulating), with the recording of truth poses
  // and GPS fixes.
  double source_seconds = 0.0;
  // The filter on controls and scans, with the recording of its estimates; trace rows excluded.
  double filter_seconds = 0.0;
  // Each scan's update (Filter::observe, what a streaming caller waits for per scan) in this
  // process: after a resume, the scans since it.
  LatencyHistogram scan_latency;
  // The associations' distances against the noise model, every scan of the run; and as they
  // stood at the last --trace row (its next row reports the scans since).
  InnovationStats innovations;
  InnovationStats innovations_at_trace_row;
  // Or "--max-steps", "--max-seconds", "input error", "error", "SIGINT", "SIGTERM".
  std::string ended_by = "end of data";
  std::optional<std::string> input_error;  // the source's message, when it ended the run
  std::optional<std::string> failure;      // what else ended it: the filter, a file
  int interrupted_by = 0;                  // the signal that ended it
  // Evaluation problems (truth that cannot score the estimate): reported, never fatal.
  std::vector<std::string> warnings;
  bool unknown_id_seen = false;  // a scan's landmark id the truth lacks was warned of
  std::uint64_t unlabelled_discarded = 0;
};

struct RunSettings {
  const RunOptions& options;  // match_radius and rpe_delta resolved (set)
  const SourceInfo& info;
  const engine::FilterConfig& config;
  const AssociationChoice& association;
  std::uint32_t particles;
};

// True when the filter's error against the run's reference (truth, else GPS) exceeds dead
// reckoning's: it did worse than ignoring every observation.
bool worse_than_dead_reckoning(const RunResult& r);

// "complete", "interrupted" or "failed: REASON": how the run ended, metrics.json's "status".
std::string run_status(const RunResult& r);

nlohmann::json metrics_json(const RunSettings& s, const RunResult& r);

// The headline and the detail lines on `out`; the dead-reckoning warning on stderr.
void print_summary(const RunSettings& s, const RunResult& r, std::FILE* out = stdout);

}  // namespace fastslam::tools
