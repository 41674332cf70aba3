// The simulated source, `--source sim`: a world (Bailey's CSV maps, or a procedural grid or
// loop of any size) driven by the simulator (tools/sim/simulator.h), one control step at a
// time: the control, the truth pose after it and the scan taken at its end, all stamped at the
// end of the step. Its log header is Bailey's car and sensor with the simulator's own noises.
//
// Ownership: plain values. Thread safety: thread-compatible. Costs: building a world is
// O(N log N) (tools/sim/world.h); the source holds the world and one step.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "tools/sim/simulator.h"
#include "tools/sim/world.h"

namespace fastslam::tools {

// The built-in default world: a grid of 10^5 landmarks, one per 2 m x 2 m, scanned once a
// second, so a default run stays dense and short (docs/scaling.md, "The built-in stress run").
inline constexpr std::uint64_t kDefaultGridLandmarks = 100'000;
inline constexpr double kDefaultGridSpacing = 2.0;     // m
inline constexpr double kDefaultGridScanPeriod = 1.0;  // s
inline constexpr double kDefaultLoopSpacing = 10.0;    // m

// The world and the simulator of a simulated source.
struct SimWorldOptions {
  // CSV files (both or neither), else a procedural world ("grid" or "loop").
  std::string landmarks_csv;
  std::string waypoints_csv;
  std::string world = "grid";
  std::uint64_t landmarks = kDefaultGridLandmarks;  // grid
  // Metres per landmark; unset: kDefaultGridSpacing on a grid, kDefaultLoopSpacing on a loop.
  std::optional<double> spacing;
  // Seconds between scans; unset: kDefaultGridScanPeriod on a grid, else config.dt_observe.
  std::optional<double> scan_period;
  double loop_length = 2000.0;  // m, loop
  SimConfig config;             // the simulator (its noises are the header's too)
};

// The world the options describe (deterministic per seed). Throws std::invalid_argument for an
// unknown world or one CSV file without the other, std::runtime_error for an unreadable file.
World make_world(const SimWorldOptions& options, std::uint64_t seed);

// The simulator's configuration with the scan period resolved.
SimConfig resolved_sim_config(const SimWorldOptions& options);

}  // namespace fastslam::tools
