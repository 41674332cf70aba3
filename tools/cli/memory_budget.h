// The memory a run's filter will need, estimated before it is built, and the refusal of a run
// whose estimate exceeds the room it has: --max-memory, else what the machine has available
// (MemAvailable in /proc/meminfo, and the cgroup's memory.max less memory.current). A run of
// 10^7 particles is refused at once with its figure instead of dying of std::bad_alloc minutes
// and gigabytes later.
//
// The estimate is a sum of terms measured on this engine (memory_budget.cc says how): per
// particle, its columns, resampling's copies, FastSLAM 2.0's pose covariance, the nodes of its
// own map path, the trajectory buffer (per control queued before a scan), the scan records and
// the map nodes a scan copies (per detection); plus, once, a map of the source's true landmarks
// (the EKF: its dense covariance). It is a lower bound when the source cannot say how many
// landmarks its map holds (no true map) or how its scans look (a pipe).
//
// Ownership: plain values. Thread safety: thread-safe (reads /proc and /sys only). Costs: the
// estimate O(1); the machine's room a few small file reads.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "engine/filter_config.h"
#include "tools/datasets/source.h"

namespace fastslam::tools {

struct MemoryEstimate {
  std::uint64_t bytes = 0;         // in all
  std::uint64_t per_particle = 0;  // of which each particle's
  std::uint64_t map_bytes = 0;     // of which the map's (the EKF: its covariance)
  std::uint64_t landmarks = 0;     // the map the estimate assumes
  ScanShape scans;                 // the largest scan it assumes
  // The source did not say how many landmarks, or how large its scans: the run needs at least
  // `bytes`.
  bool lower_bound = false;
};

// What the filter `config` needs to run `info`'s source.
MemoryEstimate estimate_filter_memory(const engine::FilterConfig& config, const SourceInfo& info);

// How much memory a run may take, and where that figure comes from (for messages).
struct MemoryRoom {
  std::uint64_t bytes = 0;
  std::string source;   // "allowed by --max-memory", "available (MemAvailable in ...)", ...
  bool option = false;  // --max-memory's
};

// The machine's room: /proc/meminfo's MemAvailable, lowered to the room left under the memory
// limit (memory.max - memory.current, cgroup v2; limit_in_bytes - usage_in_bytes, v1) of this
// process's cgroup and each of its parents. Empty when none can be read. `root` prefixes every
// path (tests give a directory laid out as / is).
std::optional<MemoryRoom> machine_memory_room(const std::string& root = "");

// The room for a run given --max-memory `max_memory` (bytes; 0: the machine's).
std::optional<MemoryRoom> memory_room(std::uint64_t max_memory, const std::string& root = "");

// The refusal of a run whose estimate exceeds the room: "--particles 10000000: the filter
// needs about 510 GiB (53 KiB per particle: ...), more than the 8.0 GiB allowed by
// --max-memory: use fewer particles or raise --max-memory". Empty when it fits.
std::optional<std::string> memory_refusal(const MemoryEstimate& estimate,
                                          const engine::FilterConfig& config,
                                          const MemoryRoom& room);

// Estimates, finds the room and throws std::invalid_argument with the refusal when the run
// does not fit; returns the estimate. Nothing is refused when the machine's room cannot be read.
MemoryEstimate check_memory_budget(const engine::FilterConfig& config, const SourceInfo& info,
                                   std::uint64_t max_memory);

// A size as --max-memory takes it: bytes ("1073741824"), or a number with a binary unit K, M,
// G or T ("512M", "1.5G"; an optional "B" or "iB" after it, any case). Throws
// std::invalid_argument for anything else or a size beyond 2^64 bytes.
std::uint64_t parse_memory_size(std::string_view text);
// The same as an option's check: `text` rewritten as its bytes in decimal and "" returned, or the
// reason it is not a size (`text` unchanged).
std::string memory_size_check(std::string& text);

// "512 B", "1.5 KiB", "11.2 GiB": bytes in binary units, 3 significant figures or one
// decimal.
std::string format_bytes(double bytes);

}  // namespace fastslam::tools
