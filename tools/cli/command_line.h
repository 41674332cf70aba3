// The `fastslam` command line's options (CLI11): `run` and `convert` options bound to a
// `RunOptions`, the words turned into the config's enums after parsing, and `--config FILE.json`
// for everything the flags set. Kept out of the installed libraries (it needs CLI11); linked by
// the `fastslam` executable and its tests.
//
// Config files: one JSON object whose keys are the long flag names without the dashes
// ("particles", "landmarks-csv", "no-progress", ...), values numbers, strings or booleans (null:
// not set, as metrics.json's "options" writes an option that means "none"). A
// flag given on the command line wins over the file (--plot over the file's "no-plot" and
// --no-plot over its "plot" too); an unknown key, a nested value or a value the flag's check
// refuses is an error naming the file and the key.
//
// Ownership: the App borrows the options it binds, which must outlive parsing.
// Thread safety: thread-compatible. Costs: negligible.
#pragma once

#include <cstdint>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json_fwd.hpp>

#include "engine/filter_config.h"
#include "tools/cli/run_command.h"

namespace fastslam::tools {

// Options parsed as words (or with "given" semantics), turned into RunOptions by finish().
struct RunWords {
  int loops = 0;
  double spacing = 0, scan_period = 0;  // given or not: RunOptions' optionals
  // Names from the engine's tables (engine/filter_config.h): the defaults of FilterConfig.
  std::string algorithm{engine::enum_name(engine::FilterConfig{}.algorithm)};
  std::string resample{engine::enum_name(engine::FilterConfig{}.resample.when)};
  std::string scheme{engine::enum_name(engine::FilterConfig{}.resample.scheme)};
  std::string motion_draw{engine::enum_name(engine::FilterConfig{}.motion_draw)};
  double sigma_range = 0, sigma_bearing = 0, sigma_control0 = 0, sigma_control1 = 0;
  double max_range = 0, field_of_view_deg = 0;
  double clutter_density = 0, detection_probability = 0;  // the filter's (ml, das)
  std::uint64_t max_steps = 0;
  std::string seeds;
  double match_radius = 0, rpe_delta = 0;
  double max_seconds = 0;
  double initial_heading_deg = 0;
  double vp_min_bearing_deg = 0, vp_max_bearing_deg = 0;  // given or not: the gate's defaults
  double vp_laser_yaw_deg = 0;
  std::string config;        // --config FILE.json
  std::string plot = "svg";  // --plot, unless --no-plot
  bool no_plot = false;
};

// Binds the options of `fastslam run` (sources, world, filter, noise overrides, outputs).
void add_run_options(CLI::App& cmd, RunOptions& options, RunWords& words);
// Binds the options of `fastslam convert` (source, world, seed, --data, --out FILE.log).
void add_convert_options(CLI::App& cmd, RunOptions& options, RunWords& words);

// --threads beyond this is refused before any thread starts: kMaxThreadsPerCore per hardware
// thread (more only adds switching: the work is split per particle block), fewer when the
// address-space limit (ulimit -v) leaves room for fewer stacks of kThreadStackBytes (TBB's
// default worker stack) in half of it, or the process limit (ulimit -u) is lower. Costs: two
// getrlimit calls.
inline constexpr std::uint64_t kMaxThreadsPerCore = 16;
inline constexpr std::uint64_t kThreadStackBytes = std::uint64_t{4} << 20;
unsigned max_startable_threads();
// The message refusing `threads`: the limit and where it comes from.
std::string threads_refusal(unsigned threads);

// Applies the JSON config file to every option of `cmd` not given on its command line.
// Throws std::runtime_error "<file>: ..." naming the key on an unknown, repeated or bad key.
void apply_json_config(CLI::App& cmd, const std::string& path);
// The same for a JSON object already in memory (the Python module's keyword arguments);
// `where` stands for the file in messages.
void apply_json_config(CLI::App& cmd, const nlohmann::json& config, const std::string& where);

// After parsing (and the config): the words into enums, the loops default, the noise overrides
// that were given, the picture (--plot, --no-plot). Reads `cmd` to see which options were given.
// Throws std::invalid_argument for `--out ""`, for more threads than max_startable_threads()
// and for --no-plot with a --plot other than none.
void finish_run_options(const CLI::App& cmd, const RunWords& words, RunOptions& options);

}  // namespace fastslam::tools
