// The linear-copy baseline against two oracles: one scan worked by hand with the engine's EKF
// functions (association, update, negative information, removal, a new landmark), and the tree
// engine itself, which with every-step systematic resampling draws the same random numbers and
// so must give the same poses and maps step for step. Plus: duplicates copy whole maps, and
// unsupported configs and bad input are refused without change.
#include "tools/studies/linear_baseline.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

#include "engine/landmark_ekf.h"
#include "tools/sim/simulator.h"
#include "tools/sim/world.h"

namespace fastslam::tools {
namespace {

engine::FilterConfig baseline_config(std::uint32_t particles) {
  engine::FilterConfig c;
  c.particles = particles;
  c.association = engine::Association::kMaximumLikelihood;
  c.threads = 1;
  c.seed = 7;
  return c;
}

engine::MapLandmark prior_landmark(std::uint64_t id, double x, double y, double log_odds) {
  return {0, id, x, y, 0.1, 0.0, 0.1, log_odds, 0};
}

TEST(LinearFastSlam, OneScanMatchesTheEkfWorkedByHand) {
  LinearFastSlam f(baseline_config(1));  // pose (0, 0, 0); dt = 0 controls would not move it
  const std::vector<engine::MapLandmark> prior = {
      prior_landmark(10, 10.0, 2.0, 5.0),   // observed: updated, log-odds + 1
      prior_landmark(11, 15.0, -6.0, 5.0),  // in view, missed: log-odds - 1
      prior_landmark(12, 20.0, 5.0, 0.5),   // in view, missed: falls below 0, removed
      prior_landmark(13, -10.0, 0.0, 5.0),  // behind the sensor (field of view pi): untouched
  };
  f.set_map(prior);
  const engine::RangeBearingModel sensor;
  const engine::Pose pose(0, 0, 0);
  Eigen::Matrix2d r;
  r << 0.01, 0, 0, std::pow(std::numbers::pi / 180, 2);
  // Landmark 10 seen slightly off its mean; and one observation of nothing known (new).
  const Eigen::Vector2d z0 = sensor.predict(Eigen::Vector2d(10.2, 1.9), pose);
  const Eigen::Vector2d z1(8.0, -1.2);
  const engine::Observation scan[] = {{z0[0], z0[1], -1}, {z1[0], z1[1], -1}};
  f.observe(scan);

  const std::vector<memory::Landmark>& map = f.map(0);
  ASSERT_EQ(map.size(), 4u);  // 10, 11, 13 kept in order, then the new one
  engine::LandmarkGaussian expected =
      engine::to_gaussian(memory::Landmark{10.0, 2.0, 0.1, 0.0, 0.1, 5.0, 10, 0});
  engine::update_landmark(sensor, expected, pose, z0, r);
  EXPECT_EQ(map[0].id, 10u);
  EXPECT_NEAR(map[0].x, expected.mean[0], 1e-12);
  EXPECT_NEAR(map[0].y, expected.mean[1], 1e-12);
  EXPECT_NEAR(map[0].sxx, expected.cov(0, 0), 1e-15);
  EXPECT_NEAR(map[0].sxy, expected.cov(0, 1), 1e-15);
  EXPECT_NEAR(map[0].syy, expected.cov(1, 1), 1e-15);
  EXPECT_EQ(map[0].log_odds, 6.0);
  EXPECT_EQ(map[1].id, 11u);
  EXPECT_EQ(map[1].log_odds, 4.0);
  EXPECT_EQ(map[2].id, 13u);
  EXPECT_EQ(map[2].log_odds, 5.0);
  const engine::LandmarkGaussian created = engine::initialize_landmark(sensor, pose, z1, r);
  EXPECT_NEAR(map[3].x, created.mean[0], 1e-12);
  EXPECT_NEAR(map[3].y, created.mean[1], 1e-12);
  EXPECT_NEAR(map[3].sxx, created.cov(0, 0), 1e-15);
  EXPECT_EQ(map[3].log_odds, 1.0);
  EXPECT_EQ(f.statistics().landmarks_created, 1u);
  EXPECT_EQ(f.statistics().landmarks_removed, 1u);
}

// With resampling every scan, the tree engine draws the same motion normals (seed, step,
// particle) and the same systematic ancestors, and its association and updates are the same
// functions: the two must agree to rounding.
TEST(LinearFastSlam, MatchesTheTreeEngineStepForStep) {
  const World world = make_grid_world(400, 10.0, 45.0, 3);
  engine::FilterConfig config = baseline_config(12);
  config.resample.when = parallel::ResamplePolicy::When::kEveryStep;
  config.resample.scheme = parallel::ResampleScheme::kSystematic;
  config.motion_draw = engine::MotionDraw::kEveryControl;  // the baseline moves control by control
  config.initial_pose[0] = world.start_x;
  config.initial_pose[1] = world.start_y;
  config.initial_pose[2] = world.start_theta;
  // Half the map known, so that new landmarks, updates and misses all happen.
  std::vector<engine::MapLandmark> prior;
  for (std::size_t i = 0; i < world.landmarks.size(); i += 2) {
    prior.push_back(prior_landmark(i, world.landmarks[i].x, world.landmarks[i].y, 3.0));
  }
  engine::Filter tree(config);
  tree.set_map(prior);
  LinearFastSlam linear(config);
  linear.set_map(prior);

  Simulator sim(world, SimConfig{}, 5);
  SimStep s;
  std::uint64_t scans = 0;
  while (scans < 60 && sim.next(s)) {
    tree.predict({s.speed, s.steer}, s.dt);
    linear.predict({s.speed, s.steer}, s.dt);
    if (!s.has_scan) continue;
    ++scans;
    std::vector<engine::Observation> scan;
    for (const SimObservation& z : s.scan) scan.push_back({z.range, z.bearing, -1});
    tree.observe(scan);
    linear.observe(scan);
  }
  ASSERT_EQ(scans, 60u);
  const engine::Estimate e = tree.estimate();
  const engine::Pose mean = linear.mean_pose();
  EXPECT_NEAR(mean[0], e.mean_pose[0], 1e-9);
  EXPECT_NEAR(mean[1], e.mean_pose[1], 1e-9);
  EXPECT_NEAR(mean[2], e.mean_pose[2], 1e-9);
  // After resampling the weights are equal, so the tree's best particle is particle 0.
  ASSERT_EQ(e.best_particle, 0u);
  std::vector<memory::Landmark> map = linear.map(0);
  std::vector<engine::MapLandmark> expected = e.map;
  std::sort(map.begin(), map.end(), [](auto& a, auto& b) { return a.id < b.id; });
  std::sort(expected.begin(), expected.end(), [](auto& a, auto& b) { return a.id < b.id; });
  ASSERT_EQ(map.size(), expected.size());
  for (std::size_t k = 0; k < map.size(); ++k) {
    SCOPED_TRACE(k);
    EXPECT_EQ(map[k].id, expected[k].id);
    EXPECT_NEAR(map[k].x, expected[k].x, 1e-9);
    EXPECT_NEAR(map[k].y, expected[k].y, 1e-9);
    EXPECT_NEAR(map[k].sxx, expected[k].sxx, 1e-12);
    EXPECT_NEAR(map[k].syy, expected[k].syy, 1e-12);
    EXPECT_EQ(map[k].log_odds, expected[k].log_odds);
  }
  const LinearStatistics& st = linear.statistics();
  EXPECT_GT(st.landmarks_created, 0u);
  EXPECT_EQ(st.landmarks_created, tree.statistics().landmarks_created);
  EXPECT_EQ(st.landmarks_removed, tree.statistics().landmarks_removed);
  EXPECT_GT(st.map_copies, 0u);
}

TEST(LinearFastSlam, EveryParticleOwnsAWholeMap) {
  const std::uint32_t m = 8;
  LinearFastSlam f(baseline_config(m));
  std::vector<engine::MapLandmark> prior;
  for (int i = 0; i < 100; ++i) prior.push_back(prior_landmark(i, 3.0 * i, 50.0, 5.0));
  f.set_map(prior);
  const auto one_map = static_cast<std::int64_t>(100 * sizeof(memory::Landmark));
  EXPECT_EQ(f.live_bytes(), m * one_map);
  f.predict({3.0, 0.0}, 0.2);
  const engine::Observation scan[] = {{10.0, 0.3, -1}};
  f.observe(scan);
  EXPECT_GE(f.live_bytes(), m * one_map);
  for (std::size_t i = 0; i < m; ++i) EXPECT_GE(f.map(i).size(), 100u);
}

TEST(LinearFastSlam, RefusesUnsupportedConfigsAndBadInput) {
  engine::FilterConfig c = baseline_config(4);
  c.algorithm = engine::Algorithm::kFastSlam2;
  EXPECT_THROW(LinearFastSlam{c}, std::invalid_argument);
  c = baseline_config(4);
  c.association = engine::Association::kKnown;
  EXPECT_THROW(LinearFastSlam{c}, std::invalid_argument);
  c = baseline_config(0);
  EXPECT_THROW(LinearFastSlam{c}, std::invalid_argument);
  c = baseline_config(4);
  c.motion_draw = engine::MotionDraw::kComposed;
  EXPECT_THROW(LinearFastSlam{c}, std::invalid_argument);

  LinearFastSlam f(baseline_config(4));
  f.set_map(std::vector<engine::MapLandmark>{prior_landmark(1, 5.0, 0.0, 5.0)});
  const std::vector<engine::MapLandmark> bad = {prior_landmark(2, 1.0, 1.0, 1.0),
                                                {0, 3, 1.0, 1.0, 0.1, 0.2, 0.1, 1.0, 0}};
  EXPECT_THROW(f.set_map(bad), std::invalid_argument);
  EXPECT_THROW(f.predict({std::nan(""), 0.0}, 0.1), std::invalid_argument);
  EXPECT_THROW(f.predict({1.0, 0.0}, -0.1), std::invalid_argument);
  const engine::Observation bad_scan[] = {{5.0, 0.0, -1}, {0.0, 0.0, -1}};
  EXPECT_THROW(f.observe(bad_scan), std::invalid_argument);
  EXPECT_EQ(f.statistics().controls, 0u);
  EXPECT_EQ(f.statistics().scans, 0u);
  for (std::size_t i = 0; i < 4; ++i) {
    ASSERT_EQ(f.map(i).size(), 1u);
    EXPECT_EQ(f.map(i)[0].id, 1u);
    EXPECT_EQ(f.map(i)[0].log_odds, 5.0);
  }
}

}  // namespace
}  // namespace fastslam::tools
