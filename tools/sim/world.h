// Simulated worlds: true landmarks and a waypoint route, read from the CSV files of Bailey's
// simulator (`../shared/data/bailey_sim/`) or generated procedurally at any size, and a static
// kd-tree over the true landmarks (nanoflann) for visibility and for matching estimates to truth.
//
// Ownership: `World` is a plain value. `TruthIndex` borrows the landmark vector it indexes,
// which must outlive it and not change.
// Thread safety: `World` is a value type. `TruthIndex` queries are const and may run
// concurrently; construction is exclusive.
// Costs: reading is O(rows); generators are O(N + route); `TruthIndex` builds in O(N log N),
// answers a radius query in O(log N + k) and a nearest query in O(log N).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

namespace fastslam::tools {

struct Point {
  double x = 0.0;
  double y = 0.0;
  friend bool operator==(const Point&, const Point&) = default;
};

struct World {
  std::vector<Point> landmarks;
  std::vector<Point> waypoints;  // visiting order; the route closes back to the first
  // Where the vehicle starts: Bailey's maps start at the origin facing +x.
  double start_x = 0.0;
  double start_y = 0.0;
  double start_theta = 0.0;
};

// Reads `id,x_m,y_m` (landmarks) and `index,x_m,y_m` (waypoints) files with a header line, as
// in ../shared/data/bailey_sim. Throws std::runtime_error naming the file, the line and what is
// wrong (wrong column count, not a number, non-finite value, no rows) and returns nothing
// partial.
World read_world_csv(const std::string& landmarks_csv, const std::string& waypoints_csv);

// Constant landmark density over a square: `landmarks` landmarks, one per `spacing` x `spacing`
// cell (uniform inside its cell), and a back-and-forth (lawnmower) route whose lanes are
// `lane_spacing` apart, so every landmark passes within lane_spacing / 2 of the route.
// Deterministic per seed. Throws std::invalid_argument on a non-positive size.
World make_grid_world(std::uint64_t landmarks, double spacing, double lane_spacing,
                      std::uint64_t seed);

// One loop of `loop_length` metres (a circle through waypoints `waypoint_spacing` apart) with
// landmarks scattered uniformly in a band `band` metres to either side of it, one per
// `spacing` x `spacing` of band area. Deterministic per seed.
World make_loop_world(double loop_length, double spacing, double band, double waypoint_spacing,
                      std::uint64_t seed);

// A static kd-tree over true landmark positions.
class TruthIndex {
 public:
  explicit TruthIndex(const std::vector<Point>& landmarks);
  ~TruthIndex();
  TruthIndex(const TruthIndex&) = delete;
  TruthIndex& operator=(const TruthIndex&) = delete;

  // Indices of the landmarks within `radius` of (x, y), in increasing index order. Appends to
  // `out` after clearing it.
  void within(double x, double y, double radius, std::vector<std::uint32_t>& out) const;
  // Index of the nearest landmark and its squared distance; REQUIRES: at least one landmark.
  std::pair<std::uint32_t, double> nearest(double x, double y) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace fastslam::tools
