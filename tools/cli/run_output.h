// What `fastslam run` writes at its end: metrics.json, landmarks.csv and true_landmarks.csv
// (when the source has them) in the output directory, beside the files streamed while it ran
// (tools/cli/run_recorder.h); the `--trace` CSV of errors over time; and the map picture drawn
// by a plot script.
//
// Ownership: borrows its inputs for the call; TraceWriter owns its file.
// Thread safety: thread-compatible. Costs: O(rows written); draw_map waits for the script.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <optional>
#include <span>
#include <string>

#include <nlohmann/json_fwd.hpp>

#include "engine/filter.h"
#include "tools/eval/particle_diagnostics.h"
#include "tools/io/log_format.h"

namespace fastslam::tools {

// `--trace`: one row every `every` scans, "t,scan,pose_error_m,landmark_rmse_m,landmarks,
// observed_landmarks,n_eff,distinct_particles,particle_spread_m,truth_spreads,nearest_weight"
// (the particle set's diagnostics, tools/eval/particle_diagnostics.h), an absent value left
// empty.
class TraceWriter {
 public:
  // Throws std::runtime_error "--trace PATH: cannot open for writing".
  TraceWriter(const std::string& path, std::uint64_t every);
  // Counts a scan; true when this one gets a row.
  bool due() { return scans_++ % every_ == 0; }
  void row(double t, std::optional<double> pose_error, std::optional<double> map_error,
           std::size_t landmarks, std::size_t observed,
           const std::optional<ParticleDiagnostics>& particles);
  // Throws std::runtime_error when the file could not be written.
  void close();

 private:
  std::string path_;
  std::uint64_t every_;
  std::ofstream file_;
  std::uint64_t scans_ = 0;
};

// What a run writes at its end.
struct RunFiles {
  const nlohmann::json* metrics = nullptr;
  std::span<const std::string> streamed;  // already in the directory, for the list
  std::span<const engine::MapLandmark> map;
  std::span<const TruthLandmark> true_landmarks;
  bool quiet = false;  // no list on stdout
};

// Creates `dir` and writes the files (true_landmarks.csv only when there are some); prints the
// list of every file of the run unless `quiet`.
// Throws std::runtime_error naming a file that cannot be written.
void write_run_files(const std::string& dir, const RunFiles& files, std::FILE* out = stdout);

// Runs `/usr/bin/python3 SCRIPT DIR`. The run's results stand whatever it does, so a failure
// is a warning on stderr naming the command and its exit status.
void draw_map(const std::string& script, const std::string& dir, std::FILE* out = stdout);

}  // namespace fastslam::tools
