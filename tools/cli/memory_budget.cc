#include "tools/cli/memory_budget.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/enum_names.h"
#include "engine/motion_dispatch.h"

namespace fastslam::tools {
namespace {

// The constants below were measured on the release build (jemalloc) with
// `fastslam run ... --threads 1 --out o`, reading peak_rss_bytes in o/metrics.json; the figures
// are resident bytes, so they include jemalloc's rounding of each block to its size class.
//
// Each particle's own share, resampling's copies of the columns and maps included: with one
// landmark and a scan after every control (`--world grid --landmarks 1 --particles 1000000
// --max-steps 400 --scan-period 0.025`) a run peaks at 672 MB (FastSLAM 1.0) and 872 MB (2.0,
// whose covariance column is 200 B); less the 8 MB of a one-particle run and the terms below
// for its leaf, one control and 0.2 detections a scan, 284 and 484 B. Rounded up: at longer
// scan periods the phases peak apart and the sum over-counts by up to ~140 B.
constexpr double kParticleBytesFastSlam1 = 290;
constexpr double kParticleBytesFastSlam2 = 490;
// Without odometry FastSLAM 2.0 carries its covariances through resampling, into a second
// column of kPoseCovStride doubles (memory/particle_store.h).
constexpr double kCarriedCovarianceBytes = 200;
// The map nodes each particle owns once it has updated a landmark: one leaf (264 B, in
// jemalloc's 320 B class; the node heap counted 264 B per particle in the runs above); with
// unknown association also the spatial index's nodes (664 B counted, --association ml).
constexpr double kOwnedNodeBytesKnown = 320;
constexpr double kOwnedNodeBytesUnknown = 800;
// The trajectory's group sums: five doubles per group of eight particles per control queued
// before a scan (engine/internal/trajectory_recorder.h), 5 B per particle and control.
constexpr double kTrajectoryBytesPerControl = 5;
// The scan records: an assignment and a distance per particle and detection
// (engine/internal/scan_report.h).
constexpr double kRecordBytesPerDetection = 16;
// The map nodes a scan copies in each particle before resampling frees the losers' (path
// copying, docs/memory.md), per detection. On the built-in stress world (295 detections a scan:
// 29474 in 100 scans) `--max-steps 4000 --particles 1000` and `3000` peak at 64.3 and 154.0 MB,
// 44.9 KiB per particle, 130 B per detection after the terms above; with --association ml
// (--particles 10 and 300: 25.4 and 43.1 MB) 185 B. FastSLAM 2.0 copies more: --algorithm
// fastslam2 peaks at 109.4 and 278.7 MB (1000 and 3000 particles), 264 B per detection; with
// --association ml at 26.0 and 50.3 MB (10 and 300), 260 B.
constexpr double kCopyBytesPerDetectionKnown = 130;
constexpr double kCopyBytesPerDetectionUnknown = 185;
constexpr double kCopyBytesPerDetectionFastSlam2 = 265;
// One map shared by every particle, with the run's copy of it for its outputs and the known-id
// table: `--max-steps 200000 --particles 1` maps all of the stress world's 100000 landmarks and
// peaks 17.8 MB above `--max-steps 400`, 178 B a landmark; with --association ml 223 B.
constexpr double kMapBytesPerLandmarkKnown = 180;
constexpr double kMapBytesPerLandmarkUnknown = 225;

bool known_ids(const engine::FilterConfig& config) {
  return config.association == engine::Association::kKnown;
}

std::optional<std::string> read_text(const std::string& path) {
  std::ifstream in(path);
  if (!in) return std::nullopt;
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// A whole decimal number, the file's only content but for white space; empty otherwise ("max").
std::optional<std::uint64_t> read_number(const std::string& path) {
  const std::optional<std::string> text = read_text(path);
  if (!text) return std::nullopt;
  std::istringstream in(*text);
  std::string word;
  in >> word;
  std::uint64_t value = 0;
  const auto [end, ec] = std::from_chars(word.data(), word.data() + word.size(), value);
  if (ec != std::errc() || end != word.data() + word.size() || word.empty()) return std::nullopt;
  return value;
}

// The value of `key` (a line "KEY VALUE" or "KEY: VALUE ..."), or empty.
std::optional<std::uint64_t> field(const std::string& text, std::string_view key) {
  std::istringstream in(text);
  std::string name;
  std::uint64_t value = 0;
  while (in >> name >> value) {
    if (!name.empty() && name.back() == ':') name.pop_back();
    if (name == key) return value;
    in.ignore(std::numeric_limits<std::streamsize>::max(), '\n');
  }
  return std::nullopt;
}

// The room under one cgroup's limit: the limit less what it holds, page cache it can drop
// (inactive files) aside. Empty without a limit.
std::optional<std::uint64_t> cgroup_room(const std::string& dir, bool v2) {
  const std::optional<std::uint64_t> limit =
      read_number(dir + (v2 ? "/memory.max" : "/memory.limit_in_bytes"));
  // v1 says "no limit" with a number near 2^63.
  if (!limit || *limit >= (std::uint64_t{1} << 62)) return std::nullopt;
  std::uint64_t used =
      read_number(dir + (v2 ? "/memory.current" : "/memory.usage_in_bytes")).value_or(0);
  if (const std::optional<std::string> stat = read_text(dir + "/memory.stat")) {
    const std::uint64_t cache =
        field(*stat, v2 ? "inactive_file" : "total_inactive_file").value_or(0);
    used -= std::min(used, cache);
  }
  return *limit - std::min(*limit, used);
}

// This process's cgroup path for the memory controller (v2: "0::PATH"; v1: "N:...memory...:PATH").
std::optional<std::string> cgroup_path(const std::string& root, bool v2) {
  const std::optional<std::string> text = read_text(root + "/proc/self/cgroup");
  if (!text) return std::nullopt;
  std::istringstream in(*text);
  std::string line;
  while (std::getline(in, line)) {
    const std::size_t a = line.find(':');
    const std::size_t b = a == std::string::npos ? a : line.find(':', a + 1);
    if (b == std::string::npos) continue;
    const std::string controllers = line.substr(a + 1, b - a - 1);
    const bool memory = v2 ? line.substr(0, a) == "0" && controllers.empty()
                           : ("," + controllers + ",").find(",memory,") != std::string::npos;
    if (memory) return line.substr(b + 1);
  }
  return std::nullopt;
}

// The least room under the limits of this process's cgroup and of its parents.
std::optional<std::uint64_t> cgroups_room(const std::string& root, bool v2) {
  const std::string base = root + (v2 ? "/sys/fs/cgroup" : "/sys/fs/cgroup/memory");
  std::string path = cgroup_path(root, v2).value_or("/");
  while (path.size() > 1 && path.back() == '/') path.pop_back();
  std::optional<std::uint64_t> least;
  for (;;) {
    const std::optional<std::uint64_t> room = cgroup_room(path == "/" ? base : base + path, v2);
    if (room) least = std::min(least.value_or(*room), *room);
    const std::size_t slash = path.rfind('/');
    if (path == "/" || slash == std::string::npos) break;
    path.resize(std::max<std::size_t>(slash, 1));  // "/a/b" -> "/a" -> "/"
  }
  return least;
}

}  // namespace

MemoryEstimate estimate_filter_memory(const engine::FilterConfig& config, const SourceInfo& info) {
  MemoryEstimate e;
  e.landmarks = info.landmarks.size();
  e.scans = info.scans;
  e.lower_bound = info.landmarks.empty() || !info.scans.known;
  const double n = static_cast<double>(e.landmarks);
  if (config.algorithm == engine::Algorithm::kEkf) {
    // engine/ekf_slam.h: a dense covariance of 8 d^2 bytes for a state of d = pose + 2N.
    const double d = engine::without_odometry(config.motion.kind) ? 5 : 3;
    const double dim = d + 2 * n;
    e.map_bytes = static_cast<std::uint64_t>(8 * dim * dim);
    e.bytes = e.map_bytes;
    return e;
  }
  const bool known = known_ids(config);
  const bool fs2 = config.algorithm == engine::Algorithm::kFastSlam2;
  double particle = fs2 ? kParticleBytesFastSlam2 : kParticleBytesFastSlam1;
  if (fs2 && engine::without_odometry(config.motion.kind)) particle += kCarriedCovarianceBytes;
  particle += known ? kOwnedNodeBytesKnown : kOwnedNodeBytesUnknown;
  if (config.record_trajectory) {
    particle += kTrajectoryBytesPerControl *
                static_cast<double>(std::max<std::uint64_t>(1, info.scans.controls));
  }
  const double copies = fs2     ? kCopyBytesPerDetectionFastSlam2
                        : known ? kCopyBytesPerDetectionKnown
                                : kCopyBytesPerDetectionUnknown;
  particle += static_cast<double>(info.scans.detections) * (kRecordBytesPerDetection + copies);
  e.per_particle = static_cast<std::uint64_t>(particle);
  e.map_bytes = static_cast<std::uint64_t>(
      n * (known ? kMapBytesPerLandmarkKnown : kMapBytesPerLandmarkUnknown));
  e.bytes = e.per_particle * config.particles + e.map_bytes;
  return e;
}

std::optional<MemoryRoom> machine_memory_room(const std::string& root) {
  std::optional<MemoryRoom> room;
  if (const std::optional<std::string> meminfo = read_text(root + "/proc/meminfo")) {
    if (const std::optional<std::uint64_t> kib = field(*meminfo, "MemAvailable")) {
      room = MemoryRoom{*kib * 1024, "available (MemAvailable in /proc/meminfo)", false};
    }
  }
  for (const bool v2 : {true, false}) {
    const std::optional<std::uint64_t> cgroup = cgroups_room(root, v2);
    if (cgroup && (!room || *cgroup < room->bytes)) {
      room = MemoryRoom{*cgroup,
                        v2 ? "left under the cgroup's memory.max"
                           : "left under the cgroup's memory.limit_in_bytes",
                        false};
    }
  }
  return room;
}

std::optional<MemoryRoom> memory_room(std::uint64_t max_memory, const std::string& root) {
  if (max_memory > 0) return MemoryRoom{max_memory, "allowed by --max-memory", true};
  return machine_memory_room(root);
}

std::optional<std::string> memory_refusal(const MemoryEstimate& e,
                                          const engine::FilterConfig& config,
                                          const MemoryRoom& room) {
  if (e.bytes <= room.bytes) return std::nullopt;
  const bool ekf = config.algorithm == engine::Algorithm::kEkf;
  const std::string landmarks =
      std::to_string(e.landmarks) + " landmark" + (e.landmarks == 1 ? "" : "s");
  const bool particles_dominate = !ekf && e.per_particle * config.particles >= e.map_bytes;
  std::string what;
  if (ekf) {
    what = "--algorithm ekf on a map of " + landmarks;
  } else if (particles_dominate) {
    what = "--particles " + std::to_string(config.particles);
  } else {
    what = "a map of " + landmarks + " with --particles " + std::to_string(config.particles);
  }
  std::string detail;
  if (ekf) {
    detail = "its dense covariance, 8 (" +
             std::string(engine::without_odometry(config.motion.kind) ? "5" : "3") +
             " + 2N)^2 bytes";
  } else {
    detail = format_bytes(static_cast<double>(e.per_particle)) + " per particle, for scans of " +
             std::to_string(e.scans.controls) + " controls and " +
             std::to_string(e.scans.detections) + " detections" + (e.scans.known ? "" : " so far") +
             "; " + format_bytes(static_cast<double>(e.map_bytes)) + " for a map of " + landmarks;
  }
  if (e.landmarks == 0) detail += "; the source does not say how many its map will hold";
  std::string remedy;
  if (ekf) {
    remedy = "use a particle filter (--algorithm fastslam1 or fastslam2) or a smaller map";
  } else if (particles_dominate) {
    remedy = "use fewer particles";
  } else {
    remedy = "use a smaller map";
  }
  remedy += room.option ? " or raise --max-memory" : ", or give --max-memory SIZE to run anyway";
  return what + ": the filter needs " + (e.lower_bound ? "at least " : "about ") +
         format_bytes(static_cast<double>(e.bytes)) + " (" + detail + "), more than the " +
         format_bytes(static_cast<double>(room.bytes)) + " " + room.source + ": " + remedy;
}

MemoryEstimate check_memory_budget(const engine::FilterConfig& config, const SourceInfo& info,
                                   std::uint64_t max_memory) {
  const MemoryEstimate estimate = estimate_filter_memory(config, info);
  const std::optional<MemoryRoom> room = memory_room(max_memory);
  if (!room) return estimate;
  if (const std::optional<std::string> refusal = memory_refusal(estimate, config, *room)) {
    throw std::invalid_argument(*refusal);
  }
  return estimate;
}

std::uint64_t parse_memory_size(std::string_view text) {
  const auto refuse = [&](const char* why) -> std::uint64_t {
    std::string quoted(text.substr(0, 80));
    if (text.size() > 80) quoted += "...";
    throw std::invalid_argument("'" + quoted + "' is not a size (" + why +
                                "): give bytes, or a number with K, M, G or T (512M, 4G)");
  };
  std::size_t digits = 0;
  while (digits < text.size() &&
         (std::isdigit(static_cast<unsigned char>(text[digits])) || text[digits] == '.')) {
    ++digits;
  }
  if (digits == 0) return refuse("no number");
  const std::string_view number = text.substr(0, digits);
  std::string suffix;
  for (const char c : text.substr(digits)) {
    suffix.push_back(static_cast<char>(std::toupper(static_cast<unsigned char>(c))));
  }
  if (suffix.size() > 2 && suffix.ends_with("IB")) {
    suffix.resize(suffix.size() - 2);
  } else if (suffix.size() > 1 && suffix.back() == 'B') {
    suffix.pop_back();
  }
  int shift = 0;
  if (suffix == "" || suffix == "B") {
    shift = 0;
  } else if (suffix == "K") {
    shift = 10;
  } else if (suffix == "M") {
    shift = 20;
  } else if (suffix == "G") {
    shift = 30;
  } else if (suffix == "T") {
    shift = 40;
  } else {
    return refuse("unknown unit");
  }
  if (shift == 0) {
    std::uint64_t bytes = 0;
    const auto [end, ec] = std::from_chars(number.data(), number.data() + number.size(), bytes);
    if (ec == std::errc::result_out_of_range) return refuse("more than 2^64 bytes");
    if (ec != std::errc() || end != number.data() + number.size()) {
      return refuse("bytes are a whole number");
    }
    return bytes;
  }
  double value = 0;
  const auto [end, ec] = std::from_chars(number.data(), number.data() + number.size(), value);
  if (ec != std::errc() || end != number.data() + number.size()) return refuse("not a number");
  const double bytes = std::ldexp(value, shift);
  if (!(bytes < 18446744073709551616.0)) return refuse("more than 2^64 bytes");
  return static_cast<std::uint64_t>(bytes);
}

std::string memory_size_check(std::string& text) {
  try {
    text = std::to_string(parse_memory_size(text));
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return {};
}

std::string format_bytes(double bytes) {
  static constexpr const char* kUnits[] = {"B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"};
  std::size_t unit = 0;
  while (bytes >= 1024 && unit + 1 < std::size(kUnits)) {
    bytes /= 1024;
    ++unit;
  }
  char text[32];
  if (unit == 0) {
    std::snprintf(text, sizeof(text), "%.0f B", bytes);
  } else {
    std::snprintf(text, sizeof(text), bytes < 100 ? "%.1f %s" : "%.0f %s", bytes, kUnits[unit]);
  }
  return text;
}

}  // namespace fastslam::tools
