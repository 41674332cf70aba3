#include "tools/sim/simulator.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>

#include <gtest/gtest.h>

#include "tests/shared_data.h"

namespace fastslam::tools {
namespace {

World webmap(const std::string& shared) {
  return read_world_csv(shared + "/data/bailey_sim/example_webmap_landmarks.csv",
                        shared + "/data/bailey_sim/example_webmap_waypoints.csv");
}

// A small world that needs no files: a square route with landmarks around it.
World square_world() {
  World world;
  world.waypoints = {{40, 0}, {40, 40}, {0, 40}, {0, 0}};
  for (int i = -2; i <= 6; ++i) {
    for (int j = -2; j <= 6; ++j) world.landmarks.push_back({i * 8.0 + 1.5, j * 8.0 - 2.5});
  }
  return world;
}

TEST(Simulator, WebmapHasTheReferenceStepAndScanCounts) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const World world = webmap(shared);
  Simulator sim(world, SimConfig{}, 1);
  SimStep step;
  std::uint64_t steps = 0, scans = 0, observations = 0;
  while (sim.next(step)) {
    ++steps;
    scans += step.has_scan;
    observations += step.scan.size();
  }
  // The MATLAB original on webmap: 17382 control steps and 1931 scans (two loops).
  EXPECT_EQ(steps, 17382u);
  EXPECT_EQ(scans, 1931u);
  // About one landmark in the front half circle per scan (2.2 in the full circle, measured along
  // the route by brute force).
  EXPECT_GT(observations, 9 * scans / 10);
  EXPECT_LT(observations, 13 * scans / 10);
  EXPECT_FALSE(sim.next(step));
}

TEST(Simulator, ScansSeeExactlyTheLandmarksInRangeAndInFront) {
  const World world = square_world();
  SimConfig config;
  config.max_range = 15.0;
  config.loops = 1;
  Simulator sim(world, config, 9);
  SimStep step;
  int scans = 0;
  while (sim.next(step)) {
    if (!step.has_scan) continue;
    ++scans;
    std::set<std::uint32_t> expected;
    for (std::uint32_t i = 0; i < world.landmarks.size(); ++i) {
      const double dx = world.landmarks[i].x - step.truth.x;
      const double dy = world.landmarks[i].y - step.truth.y;
      // Bailey's get_visible_landmarks: the half plane ahead and the range circle.
      if (dx * std::cos(step.truth.theta) + dy * std::sin(step.truth.theta) > 0 &&
          dx * dx + dy * dy < config.max_range * config.max_range &&
          dx * dx + dy * dy >= config.min_range * config.min_range) {
        expected.insert(i);
      }
    }
    std::set<std::uint32_t> seen;
    for (const SimObservation& z : step.scan) seen.insert(z.landmark);
    ASSERT_EQ(seen, expected) << "scan at step " << step.index;
  }
  EXPECT_GT(scans, 20);
}

TEST(Simulator, NoiseFreeRunFollowsTheRouteAndMeasuresExactly) {
  const World world = square_world();
  SimConfig config;
  config.control_noise = false;
  config.sensor_noise = false;
  config.loops = 1;
  Simulator sim(world, config, 1);
  SimStep step;
  std::vector<double> closest(world.waypoints.size(), INFINITY);
  while (sim.next(step)) {
    EXPECT_EQ(step.speed, config.speed);
    for (std::size_t w = 0; w < world.waypoints.size(); ++w) {
      closest[w] = std::min(closest[w], std::hypot(world.waypoints[w].x - step.truth.x,
                                                   world.waypoints[w].y - step.truth.y));
    }
    for (const SimObservation& z : step.scan) {
      const Point& l = world.landmarks[z.landmark];
      EXPECT_NEAR(z.range, std::hypot(l.x - step.truth.x, l.y - step.truth.y), 1e-12);
      EXPECT_NEAR(std::remainder(z.bearing - (std::atan2(l.y - step.truth.y, l.x - step.truth.x) -
                                              step.truth.theta),
                                 2 * std::numbers::pi),
                  0.0, 1e-12);
      EXPECT_GT(z.bearing, -std::numbers::pi);
      EXPECT_LE(z.bearing, std::numbers::pi);
    }
  }
  for (double d : closest) EXPECT_LT(d, config.at_waypoint);
}

TEST(Simulator, ControlAndSensorNoiseHaveTheConfiguredSpread) {
  const World world = square_world();
  SimConfig config;
  config.loops = 20;
  Simulator sim(world, config, 4);
  SimStep step;
  double sum = 0, sum_sq = 0, n = 0;
  double range_sq = 0, range_n = 0;
  while (sim.next(step)) {
    const double e = step.speed - config.speed;
    sum += e;
    sum_sq += e * e;
    ++n;
    for (const SimObservation& z : step.scan) {
      const Point& l = world.landmarks[z.landmark];
      const double r = z.range - std::hypot(l.x - step.truth.x, l.y - step.truth.y);
      range_sq += r * r;
      ++range_n;
    }
  }
  ASSERT_GT(n, 10000);
  // Mean within 6 standard errors; variance of a normal sample has relative sd sqrt(2/n).
  EXPECT_NEAR(sum / n, 0.0, 6 * config.sigma_v / std::sqrt(n));
  EXPECT_NEAR(sum_sq / n / (config.sigma_v * config.sigma_v), 1.0, 6 * std::sqrt(2 / n));
  EXPECT_NEAR(range_sq / range_n / (config.sigma_range * config.sigma_range), 1.0,
              6 * std::sqrt(2 / range_n));
}

TEST(Simulator, IsDeterministicPerSeed) {
  const World world = square_world();
  SimConfig config;
  config.loops = 1;
  auto run = [&](std::uint64_t seed) {
    Simulator sim(world, config, seed);
    std::vector<double> trace;
    SimStep step;
    while (sim.next(step)) {
      trace.push_back(step.speed);
      trace.push_back(step.steer);
      for (const SimObservation& z : step.scan) trace.push_back(z.range + z.bearing);
    }
    return trace;
  };
  EXPECT_EQ(run(5), run(5));
  EXPECT_NE(run(5), run(6));
}

TEST(Simulator, RefusesUnusableConfigurations) {
  const World world = square_world();
  SimConfig bad;
  bad.dt = 0;
  EXPECT_THROW(Simulator(world, bad, 1), std::invalid_argument);
  bad = SimConfig{};
  bad.sigma_v = -1;
  EXPECT_THROW(Simulator(world, bad, 1), std::invalid_argument);
  bad = SimConfig{};
  bad.loops = 0;
  EXPECT_THROW(Simulator(world, bad, 1), std::invalid_argument);
  World empty;
  EXPECT_THROW(Simulator(empty, SimConfig{}, 1), std::invalid_argument);
}

// Missed detections: with probability 1 the scans are the default's, bit for bit; with p each
// landmark in view is seen with probability p (binomial count within 5 sigma), and the ones
// seen are measured exactly as without misses.
TEST(Simulator, DetectionProbabilityThinsTheScans) {
  const World world = square_world();
  auto run = [&](double p) {
    SimConfig config;
    config.detection_probability = p;
    config.loops = 3;
    Simulator sim(world, config, 5);
    std::vector<std::vector<SimObservation>> scans;
    SimStep step;
    while (sim.next(step)) {
      if (step.has_scan) scans.push_back(step.scan);
    }
    return scans;
  };
  const auto all = run(1.0);
  SimConfig plain;
  plain.loops = 3;
  Simulator sim(world, plain, 5);
  SimStep step;
  std::size_t k = 0, total = 0;
  while (sim.next(step)) {
    if (!step.has_scan) continue;
    ASSERT_EQ(step.scan.size(), all[k].size());
    for (std::size_t j = 0; j < step.scan.size(); ++j) {
      EXPECT_EQ(step.scan[j].range, all[k][j].range);
    }
    total += step.scan.size();
    ++k;
  }
  const double p = 0.6;
  const auto thinned = run(p);
  ASSERT_EQ(thinned.size(), all.size());
  std::size_t seen = 0;
  for (std::size_t s = 0; s < all.size(); ++s) {
    seen += thinned[s].size();
    for (const SimObservation& z : thinned[s]) {
      const auto same = std::find_if(all[s].begin(), all[s].end(), [&](const SimObservation& a) {
        return a.landmark == z.landmark;
      });
      ASSERT_NE(same, all[s].end());
      EXPECT_EQ(same->range, z.range);
      EXPECT_EQ(same->bearing, z.bearing);
    }
  }
  ASSERT_GT(total, 5000u);
  const double n = static_cast<double>(total);
  EXPECT_NEAR(static_cast<double>(seen), p * n, 5 * std::sqrt(n * p * (1 - p)));
  SimConfig bad;
  bad.detection_probability = 1.5;
  EXPECT_THROW(Simulator(world, bad, 1), std::invalid_argument);
}

// A waypoint 3 m to the side of the car, which turns no tighter than 6.9 m (wheelbase 4 m,
// 30 deg): the car circles it. The run must stop, naming it, within the time it allows.
TEST(Simulator, AWaypointInsideTheTurningCircleStopsTheRunNamingIt) {
  World world;
  world.start_theta = 0.0;
  world.waypoints = {{30, 0}, {30, 3}, {0, 0}};
  world.landmarks = {{10, 10}};
  SimConfig config;
  config.at_waypoint = 0.5;
  Simulator sim(world, config, 1);
  SimStep step;
  std::uint64_t steps = 0;
  try {
    while (sim.next(step)) ++steps;
    FAIL() << "the run ended";
  } catch (const std::runtime_error& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("waypoint 2 of 3, at (30.00, 3.00), not reached"), std::string::npos)
        << message;
    EXPECT_NE(message.find("turning circle has a radius of 6.93 m"), std::string::npos) << message;
  }
  // Allowed: 3 x ((3 m + 2 pi 6.93 m) / 3 m/s + 3 s + dt) = 55.6 s after reaching waypoint 0,
  // about 10 s away.
  EXPECT_LT(static_cast<double>(steps) * config.dt, 70.0);
  EXPECT_GT(static_cast<double>(steps) * config.dt, 55.0);
}

// The same route with the side waypoint beyond the turning circle is driven to the end.
TEST(Simulator, AReachableRouteIsNotStopped) {
  World world;
  world.waypoints = {{30, 0}, {30, 30}, {0, 30}, {0, 0}};
  world.landmarks = {{10, 10}};
  Simulator sim(world, SimConfig{}, 1);
  SimStep step;
  EXPECT_NO_THROW(while (sim.next(step)){});
}

TEST(Simulator, RefusesANonPositiveWaypointRadius) {
  SimConfig bad;
  bad.at_waypoint = 0;
  EXPECT_THROW(Simulator(square_world(), bad, 1), std::invalid_argument);
}

}  // namespace
}  // namespace fastslam::tools
