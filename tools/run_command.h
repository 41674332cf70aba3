// `fastslam run`: a source of events (a simulated world: Bailey's CSV maps, or a procedural
// grid or loop of any size; or a native log file, tools/log_format.h) driven through the Filter
// by one loop, with the metrics, the estimated trajectory and the final map written to an
// output directory; and `fastslam convert`, which writes a source into a native log.
//
// Metrics against truth, whichever the source holds: pose RMSE against truth poses, landmark
// RMSE against truth landmarks (by id under known association, else to the nearest true
// landmark), GPS RMSE against GPS fixes. The estimate at a truth or GPS time is the
// weighted-mean pose after the controls up to it, linearly interpolated between the two
// estimates around it, and the fix is skipped (counted in gps_fixes_skipped) when those are
// more than kMaxInterpolationGap apart or it lies outside the run.
//
// Ownership: plain options in; files out. Thread safety: one run per call; the filter runs its
// own threads. Costs: the source plus the filter, O(steps x particles) and O(scans x
// particles x observations x log N); memory O(steps) for the trajectory and the truth.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "engine/filter_config.h"
#include "tools/simulator.h"
#include "tools/victoria_park.h"

namespace fastslam::tools {

// Estimates more than this far apart in time are not interpolated between (seconds): a truth
// pose or GPS fix falling in such a gap of the estimate is skipped. One second is 40 odometry
// periods of Victoria Park and 40 control steps of Bailey's simulator.
inline constexpr double kMaxInterpolationGap = 1.0;

// The built-in default of `fastslam run` (no source or world options): a stress run over a grid
// world of 10^5 landmarks, one per 2 m x 2 m (632 m a side), scanned once a second (~290
// detections a scan, 1.04 M in all, over 145 k control steps), with FastSLAM 1.0, M = 100.
// Chosen by measurement (README, "The built-in stress run"): at Bailey's 0.2 s scans and 10 m
// spacing the same 10^5 landmarks take 3.09 M control steps and 343 k scans (~55 s), and
// FastSLAM 1.0 loses its way (particle depletion: pose RMSE ~2 km); the denser, shorter run
// keeps it within metres (what is left is mostly a small rotation of the whole estimate).
inline constexpr std::uint64_t kDefaultGridLandmarks = 100'000;
inline constexpr double kDefaultGridSpacing = 2.0;     // m
inline constexpr double kDefaultGridScanPeriod = 1.0;  // s
inline constexpr double kDefaultLoopSpacing = 10.0;    // m

// Defaults of the no-odometry model (--motion none): the random-walk steps of v and omega per
// control (eq. 80), about a car's acceleration (1 m/s^2 gives 0.16 m/s over the 40 steps of a
// second at 40 Hz) and its steering rate. On Victoria Park (FS1, M = 100, seed 1; with the
// rear axle tracked, see run_command.cc) sigma_v 0.05 lost the heading in the unexplored west
// of the park (GPS RMSE 51 m), 0.15 kept it (5.9 m); docs/victoria-park.md.
inline constexpr double kNoOdometrySigmaV = 0.15;      // m/s per step
inline constexpr double kNoOdometrySigmaOmega = 0.05;  // rad/s per step
// The curvature walk's step (--motion none-curvature), per control. Chosen on Victoria Park by
// the filter's evidence (GPS-free; FS1, M = 100, --vp-laser-x 3.6, seeds 1-10: mean
// log_evidence 35.7 k at 0.01, 34.7 k at 0.015, seeds lost at 0.0075, every seed at 0.005:
// the driver turns the wheel from +0.23 to -0.58 rad while standing at 960 s);
// docs/victoria-park.md.
inline constexpr double kNoOdometrySigmaKappa = 0.01;  // 1/m per step

// Filter noises that replace the source's (a log header's, or the simulator's).
struct NoiseOverrides {
  std::optional<double> sigma_range, sigma_bearing, sigma_control0, sigma_control1;
};

struct RunOptions {
  std::string source = "sim";  // sim | log (convert: sim | victoria-park)
  std::string data;            // log: the log file; victoria-park: the data set's directory
  // World: CSV files, or a procedural world ("grid" or "loop").
  std::string landmarks_csv;
  std::string waypoints_csv;
  std::string world = "grid";
  std::uint64_t landmarks = kDefaultGridLandmarks;  // grid
  // Metres per landmark (density 1/spacing^2); unset: kDefaultGridSpacing on a grid,
  // kDefaultLoopSpacing on a loop.
  std::optional<double> spacing;
  // Seconds between simulated scans; unset: kDefaultGridScanPeriod on a grid world, else
  // sim.dt_observe (Bailey's 0.2 s).
  std::optional<double> scan_period;
  double loop_length = 2000.0;  // loop
  SimConfig sim;
  engine::FilterConfig filter;
  // Unknown association: estimated landmarks are paired with true ones within this distance
  // (tools/map_evaluation.h) for landmark_rmse_m and the spurious and missing counts.
  double match_radius = 5.0;
  NoiseOverrides noise;
  // "odometry": the source's motion model with its controls; "none": the controls are ignored
  // (only their dt is used) and the pose follows the Brownian velocity model of eq. 79-81
  // (engine::MotionKind::kBrownian), with `no_odometry_sigma` (the per-control increments of v,
  // m/s, and omega, rad/s; --sigma-u0/--sigma-u1 override them); "none-curvature": the same
  // with the curvature walked instead of omega (engine::MotionKind::kBrownianCurvature: a car
  // cannot turn while it stands), steps no_odometry_sigma[0] and `no_odometry_sigma_kappa`.
  std::string motion = "odometry";
  double no_odometry_sigma[2] = {kNoOdometrySigmaV, kNoOdometrySigmaOmega};
  double no_odometry_sigma_kappa = kNoOdometrySigmaKappa;  // 1/m per control
  // Replaces the source's start heading (rad) when set.
  std::optional<double> initial_heading;
  // --source victoria-park: the reader's options (gate, geometry, heading fit).
  VictoriaParkOptions victoria_park;
  std::string out;  // output directory; empty: metrics to stdout only
  // Errors over time: a CSV row every `trace_every` scans (after the scan's update) with
  // t, scan, pose_error_m (weighted-mean position against the latest truth pose, empty when the
  // source has none within kMaxInterpolationGap), landmark_rmse_m (the best particle's map
  // against the truth, by id under known association, else paired within match_radius; only
  // landmarks seen so far; empty without true landmarks), landmarks (in the best map) and
  // observed_landmarks (true landmarks seen so far). Empty: no trace, and no cost.
  // Costs per row: an estimate (O(M + N), the best map copied out) and its scoring.
  std::string trace;
  std::uint64_t trace_every = 1;
  bool progress = true;  // a progress bar on stderr when it is a terminal
  // With `out`: the matplotlib script run as `/usr/bin/python3 SCRIPT OUT` after the files are
  // written, to draw OUT/map.png (the command line sets tools/plot_run.py unless --no-plot).
  // Empty: no picture. A failing script is reported on stderr and does not fail the run.
  std::string plot_script;
};

// The plot script `fastslam run` uses by default: $FASTSLAM_PLOT_SCRIPT when set, else this
// source tree's tools/plot_run.py.
std::string default_plot_script();

// The filter's configuration for a source with header `h` under `options`: the header's
// models and noises, the options' algorithm, particles, association, ... and noise overrides;
// without odometry the Brownian model, and on an Ackermann car the rear axle tracked with the
// sensor at (a, b) from it plus the header's own sensor offset (`tracked_point_offset`).
engine::FilterConfig filter_config(const RunOptions& options, const LogHeader& h);
// Where the source's pose is relative to the point the filter tracks: zero, except without
// odometry on an Ackermann car ((a, b), the sensor from the rear axle).
engine::SensorOffset tracked_point_offset(const RunOptions& options, const LogHeader& h);

// The values --motion takes: "odometry" (the source's model), then the names of the models
// without odometry (engine::MotionKind's table).
std::vector<std::string> motion_choices();
// The no-odometry model --motion names. Throws std::invalid_argument listing motion_choices()
// for "odometry" or any other name.
engine::MotionKind no_odometry_kind(const std::string& motion);

// Runs any source (the name is historical) and returns the process exit code; throws
// std::exception with a clear message on bad options or unreadable files.
int run_simulation(const RunOptions& options);

// `fastslam convert`: writes the source (sim: the world and route of `options`, simulated with
// its seed, truth poses and landmarks included; victoria-park: the data set in `data`) as a
// native log to the file `options.out`. The file appears only when complete.
int convert_to_log(const RunOptions& options);

}  // namespace fastslam::tools
