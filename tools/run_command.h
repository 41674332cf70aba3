// `fastslam run`: a simulated world (Bailey's CSV maps, or a procedural grid or loop of any
// size) driven through the Filter (or the EKF-SLAM baseline, engine::EkfSlam, for algorithm ekf),
// with the metrics, the estimated trajectory and the final map written to an output directory.
//
// Ownership: plain options in; files out. Thread safety: one run per call; the filter runs its
// own threads. Costs: the simulation plus the filter, O(steps x particles) and O(scans x
// particles x observations x log N); for the EKF O(scans x observations x N^2).
#pragma once

#include <cstdint>
#include <string>

#include "engine/filter_config.h"
#include "tools/simulator.h"

namespace fastslam::tools {

struct RunOptions {
  std::string source = "sim";  // only simulated worlds so far
  // World: CSV files, or a procedural world ("grid" or "loop").
  std::string landmarks_csv;
  std::string waypoints_csv;
  std::string world = "grid";
  std::uint64_t landmarks = 10'000;    // grid
  double spacing = 10.0;               // grid / loop: metres per landmark (density 1/spacing^2)
  double loop_length = 2000.0;         // loop
  SimConfig sim;
  engine::FilterConfig filter;
  std::string out;            // output directory; empty: metrics to stdout only
  bool progress = true;       // a progress bar on stderr when it is a terminal
};

// Runs and returns the process exit code; throws std::exception with a clear message on bad
// options or unreadable files.
int run_simulation(const RunOptions& options);

}  // namespace fastslam::tools
