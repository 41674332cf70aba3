// The Victoria Park data set (../shared/data/victoria_park/README.md) read into a native `Log`
// (tools/io/log_format.h): odometry samples as controls (each stamped at the end of the interval
// it is held over), laser scans with their gated tree detections as scans, GPS fixes as fixes,
// in one time order (control, scan, GPS on equal times); the Ackermann car model
// (engine::AckermannModel) with this car's geometry and the laser offset in the header, and the
// start pose from the first GPS fix with a heading fitted to the GPS track. Reading is strict:
// every malformed row throws std::runtime_error
// "<file>:<line>: <reason>" and nothing is returned; detections outside the gate are dropped
// and counted. docs/victoria-park.md ("The reader") has the conventions in full.
//
// Ownership: returns values. Thread safety: thread-safe (no shared state).
// Costs: O(rows) time and memory (about 6 MB for the whole data set).
#pragma once

#include <cstddef>
#include <limits>
#include <numbers>
#include <optional>
#include <string>

#include "engine/motion_model.h"
#include "tools/io/log_format.h"

namespace fastslam::tools {

// The Victoria Park car (../shared/data/victoria_park/README.md, Guivant and Nebot), metres:
// the laser 3.78 m ahead of the rear axle and 0.50 m left of the centre line, wheelbase 2.83 m,
// the encoder wheel 0.76 m left of the centre line.
inline constexpr engine::AckermannGeometry kVictoriaParkGeometry{3.78, 0.50, 2.83, 0.76};

// Which tree detections are kept. Defaults:
// - range 5..70 m: the published FastSLAM configuration for this data set (README, RFS-SLAM
//   `cfg/fastslam_VictoriaPark.xml`). Under 5 m a trunk spans many beams and is seen
//   partially as the car passes (the detector's centre estimate is worst there); beyond 70 m
//   the detector's own 75 m beam cut truncates trunks. Together they drop about 2.6 % of the
//   52974 detections.
// - bearing within +-87.1 deg: the detector discards segments touching the scan edges, a
//   margin of about 2.9 deg on each side of the 180 deg scan (README), so anything outside is
//   not a detector output.
// - diameter: no limit. The detector keeps segments under 1 m end to end, so every detection
//   is at most about 1.1 m across; a lower limit drops the widest (bushes, groups of trunks).
struct VictoriaParkGate {
  double min_range = 5.0;                                         // m
  double max_range = 70.0;                                        // m
  double min_bearing = -(90.0 - 2.9) * std::numbers::pi / 180;    // rad, vehicle frame
  double max_bearing = (90.0 - 2.9) * std::numbers::pi / 180;     // rad
  double max_diameter = std::numeric_limits<double>::infinity();  // m
};

struct VictoriaParkOptions {
  VictoriaParkGate gate;
  engine::AckermannGeometry geometry = kVictoriaParkGeometry;
  // Noises written into the header (the filter's defaults for this source; flags override).
  // Chosen by a sweep on this data, against the published variances: docs/victoria-park.md
  // ("The filter's noises").
  double sigma_speed = 0.5;     // m/s, per 25 ms odometry sample
  double sigma_steer = 0.05;    // rad
  double sigma_range = 1.0;     // m
  double sigma_bearing = 0.05;  // rad
  // Initial heading: when unset, fitted to GPS. The odometry is dead-reckoned from the first
  // fix with heading 0 over the first `heading_fit_seconds`; the heading is the rotation about
  // the first fix that best aligns (least squares, closed form) the dead-reckoned positions at
  // the GPS times with the GPS fixes. The whole model rotates with the initial heading, so
  // this is exact for perfect odometry and uses the whole early track, curves included (the
  // direction of one chord would not). The window is the shortest with enough travel to beat
  // the GPS noise: the car stands for ~2 s, drives 22 m by 15 s and stands again until 20 s,
  // and 15 s and 20 s both give 35.9 deg (public code uses 35.5 or 36 deg). Longer windows
  // take in the dead reckoning's own heading drift (38.5 deg at 60 s, fit RMS 1.9 m), and
  // no filter can undo a wrong start heading: FastSLAM's path then comes out rotated against
  // GPS by about that difference (FS1, M = 100, no negative information, seed 1: rotated
  // -2.9 deg, GPS RMSE 6.7 m with 60 s; -0.7 deg, 3.2 m with 20 s; docs/victoria-park.md).
  std::optional<double> initial_heading;  // rad
  double heading_fit_seconds = 20.0;
  // Cut the control interval that contains a scan time into two controls (same speed and
  // steering) ending at the scan and at the next sample, so every scan is processed at the
  // pose of its own time instead of up to one odometry period (25 ms) before it. Off by
  // default: no measurable gain on FS1, M = 100 (docs/victoria-park.md).
  bool split_controls_at_scans = false;
  // The laser's yaw on the car (rad, counter-clockwise): the bearings are taken from the car's
  // heading plus this. 0 (the data set's README and public code assume an aligned laser). No
  // value is best for every filter: the detections alone give -1.1 deg
  // (tools/scripts/vp_calibrate.py), GPS prefers -0.25 to -0.75 deg depending on the filter, FS2
  // with one particle 0. Without odometry it must be set: at 0 the path rotates about 3 deg
  // (docs/victoria-park.md).
  double laser_yaw = 0.0;
};

struct VictoriaPark {
  Log log;
  std::size_t odometry_samples = 0;
  std::size_t split_controls = 0;  // extra controls from cuts at scan times
  std::size_t scans = 0;           // every scan, empty ones included
  std::size_t detections = 0;      // in tree_observations.csv
  std::size_t gated_out = 0;       // detections dropped by the gate
  std::size_t gps_fixes = 0;
  double initial_heading = 0.0;    // rad, as fitted or given
  double heading_fit_rms_m = 0.0;  // RMS distance of the fitted dead reckoning to GPS
};

// Filter settings for this data set beyond the models in the log header, which `fastslam run
// --source victoria-park` applies to every one of these options not given on its command line
// or in its config file (docs/victoria-park.md has the measurements behind them).
// - Negative information (table 1's counter form: start 1, +1 seen, remove below 0) counts a
//   tree as missed only within 20 m (`existence_range_margin` 50 m inside the 70 m gate) and
//   at half the table's penalty. The detector skips trunks that are occluded, that stand
//   within 3 m of other objects or that look not round enough from where the car is, and the
//   farther a trunk the more often it is skipped; with table 1's penalty over the whole 70 m
//   (the engine's default) real trees die between sightings and come back as new landmarks,
//   which loses the loop closures (GPS RMSE 11.4 m -> mean 13.2 m over seeds 1-5).
// - FastSLAM 2.0 uses a tighter sensor model than the header's (which is FastSLAM 1.0's): its
//   proposal draws the pose from the measurements, so the tighter they are the less noise the
//   draw adds (the paper's fig. 21). FS2, M = 1, seeds 1-5: GPS RMSE mean 52.7 m with the
//   header's 1.0 m / 0.05 rad, 3.33 m with 0.5 m / 0.02 rad; FS1, M = 100 with 0.5 m / 0.02
//   rad: 7.05 m (seeds 1-3), against 3.60 m with the header's.
// - With odometry, FastSLAM 2.0's innovations repeat from scan to scan: their lag-1
//   correlation is 0.89 (tools/scripts/innovation_correlation.py on FS2, M = 100, seeds 1-3),
//   so its weights count each scan at (1 - 0.89) / (1 + 0.89) of an independent one
//   (FilterConfig::error_correlation). FS2, M = 100, seeds 1-10: GPS RMSE mean 6.44 m -> 3.37
//   m. Without odometry it measured worse (8.19 -> 12.61 m), so it applies with odometry only.
struct VictoriaParkFilterDefaults {
  double existence_range_margin = 50.0;   // m: in view = within 70 - 50 = 20 m
  double existence_missed = 0.5;          // log-odds lost per scan in view and not seen
  double fastslam2_sigma_range = 0.5;     // m
  double fastslam2_sigma_bearing = 0.02;  // rad
  double fastslam2_error_correlation = 0.89;
};

// Reads odometry.csv, laser_scan_times.csv, tree_observations.csv and gps.csv from `dir`.
// Throws std::runtime_error (see the file comment), and std::invalid_argument for unusable
// options (a gate with min > max, a non-positive noise or fit window) or when the heading
// cannot be fitted (no movement or no GPS within the fit window; give initial_heading then).
VictoriaPark read_victoria_park(const std::string& dir, const VictoriaParkOptions& options = {});

}  // namespace fastslam::tools
