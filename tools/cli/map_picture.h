// The picture of a `fastslam run` output directory, drawn natively as DIR/map.svg from the
// files the run wrote there: truth.csv, trajectory.csv, dead_reckoning.csv, gps.csv,
// true_landmarks.csv, landmarks.csv and metrics.json, any of them absent. It shows what
// tools/scripts/plot_run.py draws into map.png with matplotlib (`--plot png`), without starting
// Python (~1.3 s): the true path, GPS fixes, the estimated path as run and moved by metrics.json's
// rigid alignment (pose_alignment, else gps_alignment), dead reckoning, the true landmarks and
// the estimated map, with 2-sigma ellipses up to kMaxEllipseLandmarks; a title with the run's
// settings and errors, a legend, equal axes in metres with round-number ticks and a grid. A map
// of more than kZoomLandmarks with a truth gets a second panel, a square holding about
// kZoomWindowLandmarks true landmarks where the true path passes nearest the map's middle, with
// each estimate joined to its true landmark under known association.
//
// The file is bounded whatever the run's length: each path is thinned to at most
// kMaxPathPoints vertices and each set of dots to at most kMaxDots (the legend then says
// "1 in N shown"); coordinates are written to 0.01 px, relative to the previous point.
//
// Ownership: nothing is kept between calls. Thread safety: thread-safe for distinct
// directories (no shared state). Costs: one streaming pass over each file (two over truth.csv
// and true_landmarks.csv when the zoom panel is drawn); memory O(kMaxPathPoints + kMaxDots),
// whatever the files' lengths; about 10 ms of CPU for the webmap run's 17382 poses, half of
// it reading, 90 ms for the built-in stress run's 145392 poses and 10^5 landmarks.
#pragma once

#include <cstddef>
#include <string>

namespace fastslam::tools {

// Paths are thinned to at most this many vertices (plus the last pose), a landmark set or the
// GPS fixes to at most kMaxDots dots, by keeping every k-th row, k a power of two.
inline constexpr std::size_t kMaxPathPoints = 20000;
inline constexpr std::size_t kMaxDots = 25000;
// The estimated map gets its 2-sigma ellipses up to this many landmarks.
inline constexpr std::size_t kMaxEllipseLandmarks = 500;
// Maps beyond this many landmarks (true or estimated) are drawn as dots, and with a truth get
// the zoom panel.
inline constexpr std::size_t kZoomLandmarks = 2000;
inline constexpr double kZoomWindowLandmarks = 150;

// Draws the run in `dir` into `dir`/map.svg, written through tools/io/atomic_file.h: whole or
// not at all. Throws std::runtime_error "FILE:LINE: reason" for a malformed CSV file (its
// header, a row), "FILE: reason" for a metrics.json that is not a JSON object or whose
// alignment lacks a number, and AtomicFile's errors when map.svg cannot be written; map.svg is
// then left as it was.
void write_map_svg(const std::string& dir);

}  // namespace fastslam::tools
