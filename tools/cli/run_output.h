// What `fastslam run` writes: the output directory checked and cleared of an earlier run's
// files before any work; at the end landmarks.csv, true_landmarks.csv (when the source has
// them) and, last, metrics.json, beside the files streamed while it ran
// (tools/cli/run_recorder.h); the `--trace` CSV of errors over time; and the map picture,
// map.svg drawn natively (tools/cli/map_picture.h) or map.png by a plot script. Every file goes
// through tools/io/atomic_file.h: it appears whole or not at all.
//
// Ownership: borrows its inputs for the call; TraceWriter owns its file.
// Thread safety: thread-compatible. Costs: O(rows written); draw_map waits for the script.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "engine/filter.h"
#include "tools/cli/map_picture.h"
#include "tools/eval/innovation_stats.h"
#include "tools/eval/particle_diagnostics.h"
#include "tools/io/atomic_file.h"
#include "tools/io/log_format.h"

namespace fastslam::tools {

// `--trace`: one row every `every` scans, "t,scan,pose_error_m,landmark_rmse_m,landmarks,
// observed_landmarks,n_eff,distinct_particles,particle_spread_m,truth_spreads,nearest_weight,
// nis_mean,landmarks_started" (the particle set's diagnostics, tools/eval/particle_diagnostics.h;
// the scan reports' mean NIS and new landmarks since the previous row,
// tools/eval/innovation_stats.h), an absent value left empty.
class TraceWriter {
 public:
  // Throws std::runtime_error "--trace PATH: ..." when PATH cannot be written (a directory,
  // a device, a directory that does not exist).
  // `keep_text`: for checkpoints (tools/cli/checkpoint.h), a copy of the file's text is kept
  // for text() (O(rows) memory).
  TraceWriter(const std::string& path, std::uint64_t every, bool keep_text = false);
  // Resumes a trace where a checkpoint left it: the file starts with `earlier` (the header and
  // the rows so far, text() of the writer that was saved) and due() goes on from `scans`.
  TraceWriter(const std::string& path, std::uint64_t every, bool keep_text,
              const std::string& earlier, std::uint64_t scans);
  // Counts a scan; true when this one gets a row.
  bool due() { return scans_++ % every_ == 0; }
  void row(double t, std::optional<double> pose_error, std::optional<double> map_error,
           std::size_t landmarks, std::size_t observed,
           const std::optional<ParticleDiagnostics>& particles, const InnovationStats& since_last);
  // Puts the rows so far in place (also after an interrupted or failed run). Throws
  // std::runtime_error when the file could not be written.
  void close();

  // The text written so far (with keep_text), and the scans due() has counted.
  const std::string& text() const { return text_; }
  std::uint64_t scans() const { return scans_; }

 private:
  void write(std::string_view line);

  std::uint64_t every_;
  AtomicFile file_;
  std::uint64_t scans_ = 0;
  bool keep_ = false;
  std::string text_;
};

// Every name `fastslam run` writes in its output directory. A run removes these (and their
// temporaries) from the directory before it starts, never anything else, so a folder never
// mixes two runs.
inline constexpr const char* kRunFileNames[] = {
    "metrics.json",       "trajectory.csv", "trajectory.tum",     "truth.csv", "gps.csv",
    "dead_reckoning.csv", "landmarks.csv",  "true_landmarks.csv", "map.svg",   "map.png"};

// Checks `dir` before a run does any work: refuses (std::runtime_error "--out DIR: ...") a
// path that is not a directory, cannot be created or written, is one of `inputs` or lies
// inside one, or holds an input under one of `names`; creates it and its missing parents.
// Returns the directories it created, `dir` first and its outermost new parent last (empty
// when `dir` existed). Costs: one probe file.
std::vector<std::string> check_output_dir(const std::string& dir,
                                          std::span<const std::string> inputs,
                                          std::span<const char* const> names);
// Removes from `dir` the `names` (and `.NAME.tmp-*` left by a killed run) that an earlier run
// left, and nothing else; throws std::runtime_error "--out DIR: ..." for one it cannot remove
// or a directory under one of the names. Costs: one directory listing.
void clear_earlier_run(const std::string& dir, std::span<const char* const> names);
// check_output_dir, then clear_earlier_run.
void prepare_output_dir(const std::string& dir, std::span<const std::string> inputs,
                        std::span<const char* const> names);

// The output directories a run created (check_output_dir's list), removed again at scope exit,
// innermost first, while they are empty (the run was refused before it wrote anything) unless
// keep() was called. Not copyable.
class CreatedDir {
 public:
  explicit CreatedDir(std::vector<std::string> dirs) : dirs_(std::move(dirs)) {}
  CreatedDir(const CreatedDir&) = delete;
  CreatedDir& operator=(const CreatedDir&) = delete;
  ~CreatedDir();
  void keep() noexcept { dirs_.clear(); }

 private:
  std::vector<std::string> dirs_;
};

// Refuses (std::runtime_error "OPTION PATH: ...") an output file `path` that is one of `inputs`
// or, in `dir` (may be empty), one of the run's `names`.
void check_output_file(const std::string& option, const std::string& path,
                       std::span<const std::string> inputs, const std::string& dir,
                       std::span<const char* const> names);

// What a run writes at its end.
struct RunFiles {
  nlohmann::json* metrics = nullptr;      // its "status" set to failed when a file fails
  std::span<const std::string> streamed;  // already in the directory, for the list
  std::span<const engine::MapLandmark> map;
  std::span<const TruthLandmark> true_landmarks;
  bool quiet = false;  // no list on stdout
};

// Writes landmarks.csv, true_landmarks.csv (when there are some) and, last, metrics.json into
// `dir` (prepared by prepare_output_dir); prints the list of the run's files written unless
// `quiet`. A file that cannot be written does not stop the others: its error is returned (one
// message per file, empty when all were written) and, when metrics["status"] was "complete",
// it becomes "failed: MESSAGE" in the metrics.json written after it.
std::vector<std::string> write_run_files(const std::string& dir, const RunFiles& files,
                                         std::FILE* out = stdout);

// Draws DIR/map.svg from the run's files in DIR (tools/cli/map_picture.h), the position files
// taken from `paths` when given, and says so on `out` unless it is null. The run's results
// stand whatever happens, so a failure (a malformed file, named with its line) is a warning on
// stderr.
void draw_map_svg(const std::string& dir, std::FILE* out, const PicturePaths* paths = nullptr);

// Runs `/usr/bin/python3 SCRIPT DIR`. The run's results stand whatever it does, so a failure
// is a warning on stderr naming the command and its exit status.
void draw_map(const std::string& script, const std::string& dir, std::FILE* out = stdout);

}  // namespace fastslam::tools
