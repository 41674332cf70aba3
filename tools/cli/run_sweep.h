// `fastslam run --seeds LIST`: one case over many seeds, because a single seed hides failures.
// Each seed runs as `fastslam run` would (into OUT/seed-S when there is an output directory),
// then every numeric metric is summarised over the seeds (mean, median, min, max, standard
// deviation; booleans as the number of seeds where true) into OUT/sweep.json, with every seed's
// metrics, and OUT/sweep.csv (a row per seed); a table of the headline errors goes to stdout.
// SIGINT or SIGTERM end the seed running (its results written, tools/cli/interrupt.h) and the
// sweep: the seeds so far are summarised, sweep.json says "status": "interrupted". A seed that
// fails after it started (a numerical failure, a bad record in the input) ends the sweep too:
// sweep.json lists it with its "status": "failed: ...", summarises the seeds before it, and
// run_sweep then throws naming the seed. An earlier sweep's sweep.json and sweep.csv are
// removed only once the first seed has been accepted (tools/cli/run_command.h run_once).
// sweep.json carries the provenance (tools/cli/run_provenance.h) once, at its top: the
// inputs hashed once, the build, the options with every seed; the seeds' entries leave it out.
//
// Ownership: plain options in; files out. Thread safety: one sweep per call; seeds run one
// after another, each with the options' threads (results do not depend on the thread count).
// Costs: the runs', plus O(seeds x metrics).
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "tools/cli/run_command.h"

namespace fastslam::tools {

// "1-10", "3", "1,4,7-9" into seeds in the order given. Throws std::invalid_argument naming the
// part that is not a seed or a range lo-hi with lo <= hi, or a seed given twice.
std::vector<std::uint64_t> parse_seeds(const std::string& text);

// The summary of metrics.json objects, one per seed: {key: {mean, median, min, max, stdev}}
// for every number (nested objects as "outer.inner"), {key: {true: count}} for booleans.
nlohmann::json summarise_seeds(const std::vector<nlohmann::json>& per_seed);

// One run of a sweep, the per-run code `fastslam run --seeds` and `fastslam sweep`
// (tools/cli/sweep_command.h) share: run_once(o, accepted)'s metrics, or for a run that failed
// after it started (RunFailed) its metrics with "status": "failed: ..." and the message in
// `failure`. A refusal before the run started propagates.
nlohmann::json run_entry(const RunOptions& o, const std::function<void()>& accepted,
                         std::string& failure);

// Moves what every run of a sweep repeats ("schema_version", "build", "options", "inputs") out
// of a run's metrics `entry` into `provenance`, keeping the first run's values there.
void take_provenance(nlohmann::json& entry, nlohmann::json& provenance);

// Writes `rows` (metrics objects, nested objects flattened as "outer.inner") as CSV to `path`
// atomically: `leading` columns first, then every other key in name order; an absent value is
// left empty. Throws std::runtime_error naming the file when it cannot be written.
void write_rows_csv(const std::string& path, const std::vector<nlohmann::json>& rows,
                    const std::vector<std::string>& leading = {});

// Prints summarise_seeds' headline errors (mean / median / worst / stdev) to stdout.
void print_headline(const nlohmann::json& summary);

// Runs `options` once per seed of options.seeds; returns the process exit code (128 + the
// signal when interrupted). Throws std::exception for a sweep refused before its first seed
// started, or, once its files are written, for a seed that failed, naming it.
int run_sweep(const RunOptions& options);

}  // namespace fastslam::tools
