// `fastslam sweep`'s plan: a sweep file (JSON) and the command line's `fastslam run` flags
// expanded to the runs of a sweep, seeds x grid x sources, each a complete RunOptions.
//
// The file is one object: "base" (`fastslam run` options, keyed as in a --config file),
// "seeds" ("1-10", as --seeds), "grid" ({"KEY": [values...]}: one axis per run option) and
// "sources" ([{"name": "webmap", KEY: value...}]: named sets of options, one axis). Every key
// of every level is checked: an unknown option, an empty or repeated axis value, a key given
// twice (in one object, or in two places that would both set it) and options that name one
// file for one run (out, trace, stream, checkpoint, resume, config) are refused with a message
// naming the file and the key. Flags on the command line win over "base", as over a run's
// --config; a flag that is also an axis is refused. The configurations are the cartesian
// product of the sources and the grid's axes (keys in name order, values in the order given),
// each named by its values ("webmap_association-ml_particles-100") and run into
// OUT/NAME/seed-S (OUT/seed-S when there are no axes).
//
// Ownership: plain values. Thread safety: thread-compatible. Costs: every configuration's
// options parsed once (CLI11), each distinct set of input files hashed once (SHA-256,
// tools/cli/run_provenance.h); O(configurations x seeds) memory.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "tools/cli/run_command.h"

namespace fastslam::tools {

// What the command line gives a sweep besides the file.
struct SweepRequest {
  std::string config;                 // --config FILE.json; empty: flags only
  std::string out;                    // --out DIR
  std::vector<std::string> grid;      // --grid KEY=V1,V2,...: axes replacing the file's KEY
  std::vector<std::string> run_args;  // the other arguments: `fastslam run` options
};

struct SweepConfiguration {
  std::string name;     // its directory under OUT ("" when the sweep has no axes)
  nlohmann::json axes;  // {"source": NAME, KEY: value, ...}: what sets it apart
  RunOptions options;   // its runs' options but for the seed and the output directory
  // The SHA-256 of its inputs (input_files_json), shared by its runs' identities.
  nlohmann::json inputs;
};

struct SweepRun {
  std::size_t configuration = 0;  // index into SweepPlan::configurations
  std::uint64_t seed = 0;
  std::string dir;  // relative to OUT: "NAME/seed-S"
  // The estimate of its cost that orders the runs, largest first: particles (1 for the EKF)
  // x --max-steps (10^6 when not given).
  double cost = 0.0;
  // run_identity (tools/cli/checkpoint.h) of its options and inputs: the build, every option
  // that changes results, the inputs' hashes. A rerun skips a run whose metrics.json is
  // complete and holds the same identity.
  nlohmann::json identity;
};

struct SweepPlan {
  std::string config_text;  // the file's bytes (empty without --config)
  std::vector<std::uint64_t> seeds;
  nlohmann::json grid;  // the axes as expanded: {"source": [...], KEY: [...]}
  std::vector<SweepConfiguration> configurations;
  std::vector<SweepRun> runs;  // configuration-major, seeds in the order given
  nlohmann::json inputs;       // every configuration's inputs, each file once
};

// Reads and expands the sweep. Throws std::runtime_error naming the file (or the flag) and
// the key for anything refused; nothing is written.
SweepPlan plan_sweep(const SweepRequest& request);

// The runs' indices in the order they are handed out: largest cost first, the plan's order
// among equals.
std::vector<std::size_t> largest_first(const SweepPlan& plan);

// The options of run `i`: its configuration's, with its seed, OUT/dir, no progress bar, no
// summary on stdout, and "sweep_run" ({configuration, seed, identity}) for metrics.json.
RunOptions run_options(const SweepPlan& plan, std::size_t i, const std::string& out);

}  // namespace fastslam::tools
