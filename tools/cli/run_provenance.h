// What metrics.json and sweep.json record so a result can be traced to what made it: the
// schema's version, the build (tools/cli/build_info.h), every option's effective value and the
// SHA-256 of each input file the run reads (docs/tools.md, "Provenance").
//
// The options object uses the --config keys (the long flag names without the dashes), with the
// values the run used: defaults included, the source's choices resolved (association, noises,
// sensor range, match radius, ...), null where an option is unset and means "none" (no
// --max-steps). Fed back as a --config file it repeats the run.
//
// Ownership: plain values in, JSON out. Thread safety: thread-safe. Costs: the options O(1);
// the inputs one extra streaming read of each file (sha256_file), never of standard input, a
// pipe or a device, which the run alone can read.
#pragma once

#include <string>

#include <nlohmann/json_fwd.hpp>

#include "engine/filter_config.h"
#include "tools/cli/run_command.h"

namespace fastslam::tools {

// Raised when a key of metrics.json changes meaning or goes away; additions keep it.
inline constexpr int kMetricsSchemaVersion = 1;

// The options object. `resolved`: the run's options with match_radius and rpe_delta set;
// `config`: the filter's configuration built from them (filter_config); `association`: the
// resolved mode ("known", "ml", "das" or "mixed").
nlohmann::json resolved_options_json(const RunOptions& resolved, const engine::FilterConfig& config,
                                     const std::string& association);

// The files the run reads, an array of {"option", "path", "bytes", "sha256"}: --config, and
// --data (every regular file under a directory, in path order) for a recorded source or the
// world CSVs for a simulated one. Standard input ("-"), pipes and devices get "sha256": null
// and "not_hashed" saying why. Throws std::runtime_error naming a file it cannot read.
nlohmann::json input_files_json(const RunOptions& options);

}  // namespace fastslam::tools
