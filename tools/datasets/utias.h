// UTIAS MRCLAM dataset 1 (../shared/data/utias_mrclam/README.md) read into a native `Log`
// (tools/io/log_format.h) for one of its five robots: odometry samples as unicycle controls
// (v, omega), the camera's detections grouped by their time as scans, Vicon poses as truth
// poses (headings glitched by the resampling repaired), in one time order (control, scan, truth
// on equal times), with the 15 Vicon landmarks
// (11 and 17 swapped back) as the true map. Detections of other robots are dropped, barcodes
// Barcodes.dat does not list pass on unlabelled (id -1); both are counted. Reading is strict:
// a malformed row throws std::runtime_error "<file>:<line>: <reason>" and nothing is
// returned. docs/utias.md has the conventions and the calibration in full.
//
// Ownership: returns values. Thread safety: thread-safe (no shared state).
// Costs: O(rows) time (about 160,000 rows per robot) and memory (about 10 MB per robot).
#pragma once

#include <array>
#include <cstddef>
#include <optional>
#include <string>

#include "tools/io/log_format.h"

namespace fastslam::tools {

// The header's noises and sensor limits, estimated from the data against Vicon by
// tools/scripts/utias_calibrate.py (its output, docs/utias.md "Calibration"; a test checks
// these equal what it prints). Control noise per 50 Hz sample, as engine::UnicycleModel draws
// it, from 1 s windows; sensor sigmas robust (1.4826 x MAD) over all five robots; field of
// view twice the nearer of the bearings' 1 % and 99 % quantiles, max range their 99 %.
inline constexpr double kUtiasSigmaV = 0.0509;        // m/s per sample
inline constexpr double kUtiasSigmaOmega = 0.132;     // rad/s per sample
inline constexpr double kUtiasSigmaRange = 0.116;     // m
inline constexpr double kUtiasSigmaBearing = 0.0103;  // rad
inline constexpr double kUtiasMaxRange = 7.32;        // m
inline constexpr double kUtiasFieldOfView = 1.06;     // rad
// The header's sensor noise is the calibration's times this width: with the barcodes as ids, the
// smallest width (in steps of 0.25) that leaves at most 5 % of the innovations beyond the
// chi-square 95 % point, pooled over robots 1-5 and seeds 1-3 (tools/scripts/noise_width.py;
// docs/utias.md, "The filter's sensor width"). The innovations also carry the pose's and map's
// error, which the odometry's time-correlated error makes wider than independent noises say.
inline constexpr double kUtiasSensorWidth = 2.5;
// Seconds each robot's odometry leads its Vicon motion (the shift that best aligns the two,
// from the same script), robots 1-5: the reader stamps every control this much later.
inline constexpr std::array<double, 5> kUtiasOdometryLead = {0.14, 0.14, 0.16, 0.16, 0.22};

inline constexpr int kUtiasRobots = 5;             // subjects 1-5; the others are landmarks
inline constexpr double kUtiasPeriod = 0.02;       // s: odometry and Vicon rows, 50 Hz from 0
inline constexpr double kUtiasExactBefore = 1000;  // s: later times print rounded to 0.1 s
// rad per Vicon row: a heading changing faster is a glitch of the resampling (the robots turn
// at most 0.57 rad/s, 0.011 rad per row); runs of at most kUtiasMaxGlitchRows such rows (the
// longest in dataset 1 is 4) are repaired (utias.cc repair_headings).
inline constexpr double kUtiasMaxHeadingStep = 0.05;
inline constexpr std::size_t kUtiasMaxGlitchRows = 10;

struct UtiasOptions {
  int robot = 1;  // 1..kUtiasRobots
  // Every truth_every-th Vicon row is a truth pose (5: 10 Hz, plenty for scoring a path at
  // 0.1 m/s and a fifth of the events).
  int truth_every = 5;
  // Unlabelled detections (barcodes Barcodes.dat does not list): passed on with id -1, or
  // dropped (known association refuses them). Counted either way. `--source utias` sets it
  // from SourceOptions::clutter.
  bool unlabelled = true;
  // Seconds the odometry leads the motion, in [0, kUtiasMaxOdometryLead]: each control is
  // stamped this much later than its row. Unset: the robot's kUtiasOdometryLead; 0: the rows'
  // own times.
  std::optional<double> odometry_lead;
};
inline constexpr double kUtiasMaxOdometryLead = 1.0;  // s

// The lead `options` gives: its odometry_lead, else the robot's calibrated one. REQUIRES: a
// robot in 1..kUtiasRobots.
double utias_odometry_lead(const UtiasOptions& options);

struct Utias {
  Log log;
  int robot = 0;
  std::size_t odometry_samples = 0;
  std::size_t truth_rows = 0;               // Vicon rows read
  std::size_t truth_poses = 0;              // of them, every truth_every-th
  std::size_t truth_headings_repaired = 0;  // Vicon rows whose heading was a glitch
  std::size_t measurements = 0;             // rows of RobotN_Measurement.dat
  std::size_t scans = 0;                    // detections grouped by time
  std::size_t landmark_detections = 0;      // with a landmark's subject as id
  std::size_t robot_detections_dropped = 0;
  std::size_t unlabelled_detections = 0;  // passed on (id -1) or dropped, as options say
  std::size_t rounded_measurements = 0;   // at t >= 1000 s: up to 0.05 s off (docs/utias.md)
  std::size_t repeated_in_scan = 0;       // a landmark twice at one time: a new scan, same time
};

// Reads Barcodes.dat, Landmark_Groundtruth.dat and RobotN_{Odometry,Measurement,Groundtruth}.dat
// from `dir` (the dataset1 directory). Throws std::invalid_argument for a robot outside
// 1..kUtiasRobots, truth_every < 1 or an odometry lead outside [0, kUtiasMaxOdometryLead],
// std::runtime_error for a missing file (naming it and
// what `dir` should be) or a malformed row (see the file comment).
Utias read_utias(const std::string& dir, const UtiasOptions& options = {});

}  // namespace fastslam::tools
