#include "tools/sim/world.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "tests/shared_data.h"

namespace fastslam::tools {
namespace {

// Brute force: indices of points strictly within `radius`, ascending.
std::vector<std::uint32_t> brute_within(const std::vector<Point>& points, double x, double y,
                                        double radius) {
  std::vector<std::uint32_t> out;
  for (std::uint32_t i = 0; i < points.size(); ++i) {
    const double dx = points[i].x - x;
    const double dy = points[i].y - y;
    if (dx * dx + dy * dy < radius * radius) out.push_back(i);
  }
  return out;
}

TEST(TruthIndex, AgreesWithBruteForce) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> coord(-500, 500);
  std::vector<Point> points(5000);
  for (Point& p : points) p = {coord(rng), coord(rng)};
  points.push_back(points[17]);  // a duplicate position
  TruthIndex index(points);
  std::vector<std::uint32_t> found;
  for (int q = 0; q < 500; ++q) {
    const double x = coord(rng) * 1.2;
    const double y = coord(rng) * 1.2;
    const double radius = std::uniform_real_distribution<double>(0, 80)(rng);
    index.within(x, y, radius, found);
    ASSERT_EQ(found, brute_within(points, x, y, radius)) << "query " << q;
    const auto [nearest, d2] = index.nearest(x, y);
    double best = INFINITY;
    for (const Point& p : points)
      best = std::min(best, (p.x - x) * (p.x - x) + (p.y - y) * (p.y - y));
    EXPECT_DOUBLE_EQ(d2, best);
    EXPECT_DOUBLE_EQ((points[nearest].x - x) * (points[nearest].x - x) +
                         (points[nearest].y - y) * (points[nearest].y - y),
                     best);
  }
}

TEST(World, ReadsBaileyWebmap) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const World world = read_world_csv(shared + "/data/bailey_sim/example_webmap_landmarks.csv",
                                     shared + "/data/bailey_sim/example_webmap_waypoints.csv");
  ASSERT_EQ(world.landmarks.size(), 35u);
  ASSERT_EQ(world.waypoints.size(), 17u);
  EXPECT_NEAR(world.landmarks[0].x, 2.992211838, 1e-12);
  EXPECT_NEAR(world.waypoints[0].y, -41.58878505, 1e-12);
  double route = 0;  // the README: a closed loop of 634.9 m
  for (std::size_t i = 0; i < world.waypoints.size(); ++i) {
    const Point& a = world.waypoints[i];
    const Point& b = world.waypoints[(i + 1) % world.waypoints.size()];
    route += std::hypot(b.x - a.x, b.y - a.y);
  }
  EXPECT_NEAR(route, 634.9, 0.05);
}

TEST(World, GridHasConstantDensityAndARouteThatCoversIt) {
  const std::uint64_t n = 10'000;
  const double spacing = 5.0;
  const double lane = 40.0;
  const World world = make_grid_world(n, spacing, lane, 3);
  ASSERT_EQ(world.landmarks.size(), n);
  const double side = 100 * spacing;  // ceil(sqrt(10^4)) = 100 cells a side
  // One landmark per cell: count per 50 m x 50 m block is exactly 100.
  std::vector<int> blocks(100, 0);
  for (const Point& p : world.landmarks) {
    ASSERT_GE(p.x, 0.0);
    ASSERT_LT(p.x, side);
    ASSERT_GE(p.y, 0.0);
    ASSERT_LT(p.y, side);
    ++blocks[static_cast<int>(p.y / 50) * 10 + static_cast<int>(p.x / 50)];
  }
  for (int count : blocks) EXPECT_EQ(count, 100);
  // Every landmark lies within lane / 2 of a lane (a horizontal route segment).
  for (const Point& p : world.landmarks) {
    double best = INFINITY;
    for (std::size_t i = 0; i + 1 < world.waypoints.size(); i += 2) {
      best = std::min(best, std::abs(p.y - world.waypoints[i].y));
    }
    ASSERT_LE(best, lane / 2 + 1e-9);
  }
  // Deterministic per seed, different across seeds.
  EXPECT_EQ(make_grid_world(n, spacing, lane, 3).landmarks, world.landmarks);
  EXPECT_NE(make_grid_world(n, spacing, lane, 4).landmarks, world.landmarks);
  EXPECT_THROW(make_grid_world(0, spacing, lane, 3), std::invalid_argument);
  EXPECT_THROW(make_grid_world(n, -1, lane, 3), std::invalid_argument);
}

TEST(World, LoopHasTheRequestedLengthAndBand) {
  const double length = 2000.0;
  const World world = make_loop_world(length, 10.0, 20.0, 10.0, 5);
  const double radius = length / (2 * M_PI);
  EXPECT_EQ(world.landmarks.size(), static_cast<std::size_t>(length * 40 / 100));
  for (const Point& p : world.landmarks) {
    const double r = std::hypot(p.x, p.y - radius);
    EXPECT_GE(r, radius - 20 - 1e-9);
    EXPECT_LE(r, radius + 20 + 1e-9);
  }
  double route = 0;
  for (std::size_t i = 0; i < world.waypoints.size(); ++i) {
    const Point& a = world.waypoints[i];
    const Point& b = world.waypoints[(i + 1) % world.waypoints.size()];
    route += std::hypot(b.x - a.x, b.y - a.y);
  }
  EXPECT_NEAR(route, length, 0.01 * length);
  EXPECT_THROW(make_loop_world(100, 10, 50, 10, 1), std::invalid_argument);
}

}  // namespace
}  // namespace fastslam::tools
