#include "tools/sim/world.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <nanoflann.hpp>
#include <numbers>
#include <stdexcept>
#include <string>

#include "parallel/random_stream.h"
#include "tools/io/csv.h"

namespace fastslam::tools {
namespace {

// Stream index of world generation (the simulator's own noise uses 0 and 1).
constexpr std::uint32_t kWorldStream = 2;

std::vector<Point> read_points(const std::string& path, const char* first_column) {
  CsvReader reader(path, {first_column, "x_m", "y_m"});
  std::vector<Point> points;
  std::array<double, 3> row{};
  while (reader.next(row)) points.push_back({row[1], row[2]});
  if (points.empty()) reader.fail("no rows");
  return points;
}

}  // namespace

World read_world_csv(const std::string& landmarks_csv, const std::string& waypoints_csv) {
  World world;
  world.landmarks = read_points(landmarks_csv, "id");
  world.waypoints = read_points(waypoints_csv, "index");
  return world;
}

World make_grid_world(std::uint64_t landmarks, double spacing, double lane_spacing,
                      std::uint64_t seed) {
  if (landmarks == 0 || !(spacing > 0) || !(lane_spacing > 0)) {
    throw std::invalid_argument("grid world: landmarks, spacing and lane spacing must be positive");
  }
  World world;
  const auto columns = static_cast<std::uint64_t>(std::ceil(std::sqrt(double(landmarks))));
  const std::uint64_t rows = (landmarks + columns - 1) / columns;
  world.landmarks.reserve(landmarks);
  for (std::uint64_t i = 0; i < landmarks; ++i) {
    parallel::RandomStream rng({seed, i, kWorldStream, parallel::Purpose::kSimulator});
    const double cx = static_cast<double>(i % columns) * spacing;
    const double cy = static_cast<double>(i / columns) * spacing;
    world.landmarks.push_back({cx + rng.uniform() * spacing, cy + rng.uniform() * spacing});
  }
  const double width = static_cast<double>(columns) * spacing;
  const double height = static_cast<double>(rows) * spacing;
  const double margin = lane_spacing / 2;
  bool east = true;
  for (double y = lane_spacing / 2; y < height + lane_spacing / 2; y += lane_spacing) {
    world.waypoints.push_back({east ? -margin : width + margin, y});
    world.waypoints.push_back({east ? width + margin : -margin, y});
    east = !east;
  }
  world.start_x = world.waypoints[0].x - margin;
  world.start_y = world.waypoints[0].y;
  world.start_theta = 0.0;
  return world;
}

World make_loop_world(double loop_length, double spacing, double band, double waypoint_spacing,
                      std::uint64_t seed) {
  if (!(loop_length > 0) || !(spacing > 0) || !(band > 0) || !(waypoint_spacing > 0)) {
    throw std::invalid_argument("loop world: every size must be positive");
  }
  const double radius = loop_length / (2 * std::numbers::pi);
  if (band >= radius) throw std::invalid_argument("loop world: band wider than the loop radius");
  World world;
  // Counter-clockwise circle through the origin, centred at (0, radius): start at the origin
  // facing +x, on the route.
  const auto points = std::max<std::uint64_t>(8, std::uint64_t(loop_length / waypoint_spacing));
  for (std::uint64_t k = 1; k <= points; ++k) {
    const double a = 2 * std::numbers::pi * static_cast<double>(k) / static_cast<double>(points);
    world.waypoints.push_back({radius * std::sin(a), radius - radius * std::cos(a)});
  }
  const auto count = static_cast<std::uint64_t>(loop_length * 2 * band / (spacing * spacing));
  const double r_in = radius - band;
  const double r_out = radius + band;
  for (std::uint64_t i = 0; i < count; ++i) {
    parallel::RandomStream rng({seed, i, kWorldStream, parallel::Purpose::kSimulator});
    const double a = 2 * std::numbers::pi * rng.uniform();
    const double r = std::sqrt(r_in * r_in + rng.uniform() * (r_out * r_out - r_in * r_in));
    world.landmarks.push_back({r * std::sin(a), radius - r * std::cos(a)});
  }
  return world;
}

// nanoflann's dataset adaptor over the borrowed landmark vector.
struct TruthIndex::Impl {
  struct Adaptor {
    const std::vector<Point>* points;
    std::size_t kdtree_get_point_count() const { return points->size(); }
    double kdtree_get_pt(std::size_t i, std::size_t dim) const {
      return dim == 0 ? (*points)[i].x : (*points)[i].y;
    }
    template <class Box>
    bool kdtree_get_bbox(Box&) const {
      return false;
    }
  };
  using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, Adaptor>,
                                                   Adaptor, 2, std::uint32_t>;
  explicit Impl(const std::vector<Point>& landmarks)
      : adaptor{&landmarks}, tree(2, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(16)) {
    tree.buildIndex();
  }
  Adaptor adaptor;
  Tree tree;
};

TruthIndex::TruthIndex(const std::vector<Point>& landmarks)
    : impl_(std::make_unique<Impl>(landmarks)) {}

TruthIndex::~TruthIndex() = default;

void TruthIndex::within(double x, double y, double radius, std::vector<std::uint32_t>& out) const {
  out.clear();
  std::vector<std::pair<std::uint32_t, double>> matches;
  const double query[2] = {x, y};
  impl_->tree.radiusSearch(query, radius * radius, matches, nanoflann::SearchParams(32, 0, false));
  for (const auto& [index, distance_sq] : matches) {
    // nanoflann's radius bound is inclusive; ours is strict (Bailey's simulator).
    if (distance_sq < radius * radius) out.push_back(index);
  }
  std::sort(out.begin(), out.end());
}

std::pair<std::uint32_t, double> TruthIndex::nearest(double x, double y) const {
  std::uint32_t index = 0;
  double distance_sq = 0.0;
  const double query[2] = {x, y};
  impl_->tree.knnSearch(query, 1, &index, &distance_sq);
  return {index, distance_sq};
}

}  // namespace fastslam::tools
