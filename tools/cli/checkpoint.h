// A run's checkpoint: what `fastslam run --resume` needs to go on after a kill and end with the
// files an uninterrupted run writes, byte for byte. It holds the filter's state (Filter::save),
// how many of the source's events were consumed, every estimated pose handed to the recorder so
// far (replayed with the source's events, they rebuild the trajectory files, dead reckoning and
// every score: tools/cli/run_command.cc), the trace's rows, the run's counters and warnings, and
// what identifies the run: the build, the options that change results, the inputs' SHA-256.
//
// Format: "FSLAMCKP", a u32 version, then length-prefixed sections (a JSON header, the trace's
// bytes, the poses as 32-byte records), the filter's state to 32 bytes before the end, and the
// SHA-256 of everything before those 32 bytes: a torn or altered file is refused whole.
//
// Ownership: plain values. Thread safety: thread-compatible. Costs: write streams the state
// through the hash into an atomic file (tools/io/atomic_file.h: the previous checkpoint stays
// until the new one is whole); read holds the whole file in memory while the filter loads.
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "engine/filter.h"

namespace fastslam::tools {

// Raised when the format changes; a checkpoint of another version is refused.
inline constexpr std::uint32_t kCheckpointVersion = 1;

struct Checkpoint {
  // {"build": ..., "options": ..., "inputs": ...}: compared whole on resume.
  nlohmann::json identity;
  // Where the run stood: events consumed from the source, controls and scans among them.
  std::uint64_t events = 0, controls = 0, scans = 0;
  // The run's own state (tools/cli/run_report.h RunResult, the trace writer's scan count) as
  // JSON, read back by the run.
  nlohmann::json run;
  std::string trace;                           // the trace file's bytes so far
  std::vector<engine::TrajectoryPoint> poses;  // every pose handed to the recorder, in order
  std::string filter_state;                    // Filter::save's bytes
};

// Writes `c` to `path` atomically, with `poses` and `filter`'s state in place of c.poses and
// c.filter_state (ignored), so neither is copied in memory first. Throws std::runtime_error
// naming the file and the reason.
void write_checkpoint(const std::string& path, const Checkpoint& c,
                      std::span<const engine::TrajectoryPoint> poses, const engine::Filter& filter);

// Reads and checks a checkpoint: magic, version, section sizes against the file's, the hash and
// the header's fields. Throws std::runtime_error "PATH: ..." saying what is wrong.
Checkpoint read_checkpoint(const std::string& path);
// As read_checkpoint on a file's bytes; `name` is the file's, for messages.
Checkpoint parse_checkpoint(const std::string& name, std::string_view bytes);

// The identity of a run: the build (tools/cli/build_info.h), its options
// (tools/cli/run_provenance.h resolved_options_json) without those that change no result
// (threads, grain, split seconds, the output paths, the budgets, the progress bar, the picture)
// and its inputs (input_files_json).
nlohmann::json run_identity(const nlohmann::json& options, const nlohmann::json& inputs);

// Refuses (std::runtime_error "--resume PATH: ...", naming the first difference and what to do)
// a checkpoint whose identity differs from `now`'s: another build, another option that changes
// results, or another input.
void check_same_run(const std::string& path, const nlohmann::json& saved,
                    const nlohmann::json& now);

// The filter the checkpoint holds, running with `execution`'s threads, grain and split seconds.
// Throws std::runtime_error "PATH: ..." when the state is not one.
std::unique_ptr<engine::Filter> load_filter(const std::string& path, const Checkpoint& c,
                                            const engine::FilterConfig& execution);

}  // namespace fastslam::tools
