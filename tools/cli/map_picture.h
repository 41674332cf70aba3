// The picture of a `fastslam run` output directory, drawn natively as DIR/map.svg from the
// files the run wrote there: truth.csv, trajectory.csv, dead_reckoning.csv, gps.csv,
// true_landmarks.csv, landmarks.csv and metrics.json, any of them absent. It shows what
// tools/scripts/plot_run.py draws into map.png with matplotlib (`--plot png`), without starting
// Python (~1.3 s): the true path, GPS fixes, the estimated path as run and moved by metrics.json's
// rigid alignment (pose_alignment, else gps_alignment), dead reckoning, the true landmarks and
// the estimated map, with 2-sigma ellipses up to kMaxEllipseLandmarks; a title with the run's
// settings and errors, a legend, equal axes in metres with round-number ticks and a grid. A map
// of more than kZoomLandmarks with a truth gets a second panel, a square holding about
// kZoomWindowLandmarks true landmarks where the true path (its drawn vertices) passes nearest
// the map's middle, with each estimate joined to its true landmark under known association.
//
// The file is bounded whatever the run's length: each path is thinned to at most
// kMaxPathPoints vertices and each set of dots to at most kMaxDots (the legend then says
// "1 in N shown"); coordinates are written to 0.01 px, relative to the previous point.
//
// A run hands the picture its paths as it wrote them (PicturePaths), so that drawing reads back
// only the small files; write_map_svg(dir) alone reads every file.
//
// Ownership: nothing is kept between calls. Thread safety: thread-safe for distinct
// directories (no shared state). Costs: one streaming pass over each file not handed over (a
// second over truth.csv, trajectory.csv and true_landmarks.csv when the zoom panel is drawn);
// memory O(kMaxPathPoints + kMaxDots), whatever the files' lengths. For the webmap run's 17382
// poses, 125 M instructions reading every file, 38 M with the paths handed over (callgrind).
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

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

// Every stride-th row kept, the stride doubling (and every other kept row dropped) whenever
// `limit` would be passed: at most `limit` rows of any number, evenly spread, in one pass.
template <class T>
class Thinned {
 public:
  explicit Thinned(std::size_t limit) : limit_(limit) {}

  // Offers row `row`'s value; rows come in increasing order.
  void add(std::uint64_t row, const T& value) {
    last_ = {row, value};
    ++offered_;
    if ((row & (stride_ - 1)) != 0) return;  // the stride is a power of two
    if (kept_.size() >= limit_) {
      stride_ *= 2;
      std::erase_if(kept_, [m = stride_ - 1](const Kept& k) { return (k.row & m) != 0; });
      if ((row & (stride_ - 1)) != 0) return;
    }
    kept_.push_back({row, value});
  }

  // The kept values; `with_last`: and the last one offered (a path's end), if it was dropped.
  std::vector<T> values(bool with_last = false) const {
    std::vector<T> out;
    out.reserve(kept_.size() + 1);
    for (const Kept& k : kept_) out.push_back(k.value);
    if (with_last && offered_ > 0 && (kept_.empty() || kept_.back().row != last_.row)) {
      out.push_back(last_.value);
    }
    return out;
  }
  std::uint64_t stride() const { return stride_; }
  std::uint64_t offered() const { return offered_; }

 private:
  struct Kept {
    std::uint64_t row = 0;
    T value{};
  };
  std::size_t limit_;
  std::uint64_t stride_ = 1;
  std::uint64_t offered_ = 0;
  std::vector<Kept> kept_;
  Kept last_;
};

// One of the run's position files as the picture takes it, row by row: the rows Thinned keeps
// and the box of every row. A run fills these as it writes the files (PicturePaths), so that
// the picture does not read them back.
class PicturePath {
 public:
  struct Point {
    double x = 0, y = 0;
  };
  explicit PicturePath(std::size_t limit) : rows_(limit) {}
  void add(double x, double y) {
    rows_.add(rows_.offered(), {x, y});
    x0_ = std::min(x0_, x), x1_ = std::max(x1_, x);
    y0_ = std::min(y0_, y), y1_ = std::max(y1_, y);
  }
  const Thinned<Point>& rows() const { return rows_; }
  // The box of every row: (x0, x1, y0, y1); x0 > x1 when no row came.
  std::array<double, 4> box() const { return {x0_, x1_, y0_, y1_}; }

 private:
  Thinned<Point> rows_;
  double x0_ = std::numeric_limits<double>::infinity(), x1_ = -x0_, y0_ = x0_, y1_ = -x0_;
};

// truth.csv, trajectory.csv, dead_reckoning.csv and gps.csv, each fed the values its text
// holds (what reading the file back gives), so that the picture drawn from them is the one
// drawn from the files. A run's writer thread fills each path while it writes that file.
struct PicturePaths {
  PicturePath truth{kMaxPathPoints}, estimate{kMaxPathPoints}, dead_reckoning{kMaxPathPoints};
  PicturePath gps{kMaxDots};
};

// Draws the run in `dir` into `dir`/map.svg, written through tools/io/atomic_file.h: whole or
// not at all. With `paths`, the four position files are taken from it rather than read (a large
// map's zoom panel still reads truth.csv and trajectory.csv near its window). Throws
// std::runtime_error "FILE:LINE: reason" for a malformed CSV file (its header, a row), "FILE:
// reason" for a metrics.json that is not a JSON object or whose alignment lacks a number, and
// AtomicFile's errors when map.svg cannot be written; map.svg is then left as it was.
void write_map_svg(const std::string& dir, const PicturePaths* paths = nullptr);

}  // namespace fastslam::tools
