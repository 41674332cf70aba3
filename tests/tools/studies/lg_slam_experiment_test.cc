#include "tools/studies/lg_slam_experiment.h"

#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <unistd.h>
#include <vector>

#include <gtest/gtest.h>

#include "tests/tools/temp_path.h"

namespace fastslam::tools {
namespace {

using testing::temp_path;

// The tiny run of `fastslam experiment lg-slam --tiny` (3 seeds, 2000 steps): the CSV has the
// contracted header, one row per recorded step, seed and variant, finite errors, and the map
// errors shrink: the mean over the seeds of the landmark error over steps >= 1500 is below 0.75
// (anchored) and 0.4 (relative) of its mean over steps 1..10. Measured over five disjoint
// triples of seeds: ratios 0.41 .. 0.59 (anchored) and 0.10 .. 0.17 (relative). The pose error
// does not go to zero (a single particle's pose is a draw from the proposal); it stays near
// 0.1 m.
TEST(LgSlamExperiment, TinyRunWritesTheCsvAndTheMapErrorsShrink) {
  LgSlamExperimentOptions options;
  options.out = temp_path("lg_slam");
  options.tiny = true;
  ASSERT_EQ(run_lg_slam_command(options), 0);

  std::ifstream in(options.out + "/lg_slam.csv");
  ASSERT_TRUE(in.good());
  std::string line;
  ASSERT_TRUE(std::getline(in, line));
  EXPECT_EQ(line, "step,seed,variant,landmark_error,pose_error");

  constexpr std::uint64_t kSteps = 2000;
  std::uint64_t recorded = 0;
  for (std::uint64_t t = 1; t <= kSteps; ++t) recorded += lg_slam_recorded_step(t, kSteps) ? 1 : 0;

  struct Sums {
    double early = 0.0, late = 0.0, late_pose = 0.0;
    int n_early = 0, n_late = 0;
  };
  std::map<std::string, Sums> sums;
  std::map<std::pair<std::uint64_t, std::string>, std::uint64_t> last_step;
  std::size_t rows = 0;
  while (std::getline(in, line)) {
    ++rows;
    std::stringstream fields(line);
    std::string step, seed, variant, landmark, pose;
    ASSERT_TRUE(std::getline(fields, step, ',') && std::getline(fields, seed, ',') &&
                std::getline(fields, variant, ',') && std::getline(fields, landmark, ',') &&
                std::getline(fields, pose))
        << line;
    const std::uint64_t t = std::stoull(step);
    const double lm = std::stod(landmark);
    const double ps = std::stod(pose);
    ASSERT_TRUE(variant == "anchored" || variant == "relative") << line;
    ASSERT_TRUE(std::isfinite(lm) && lm >= 0.0 && std::isfinite(ps) && ps >= 0.0) << line;
    ASSERT_TRUE(lg_slam_recorded_step(t, kSteps)) << line;
    auto& prev = last_step[{std::stoull(seed), variant}];
    ASSERT_GT(t, prev) << line;  // steps ascend within a run
    prev = t;
    Sums& s = sums[variant];
    if (t <= 10) {
      s.early += lm;
      ++s.n_early;
    }
    if (t >= 1500) {
      s.late += lm;
      s.late_pose += ps;
      ++s.n_late;
    }
  }
  EXPECT_EQ(rows, 3 * 2 * recorded);
  EXPECT_EQ(last_step.size(), 6u);  // seeds 1..3, both variants
  for (const auto& [key, step] : last_step) EXPECT_EQ(step, kSteps);
  const double bound[2] = {0.75, 0.4};
  int i = 0;
  for (const char* variant : {"anchored", "relative"}) {
    const Sums& s = sums[variant];
    ASSERT_GT(s.n_early, 0);
    ASSERT_GT(s.n_late, 0);
    const double early = s.early / s.n_early;
    const double late = s.late / s.n_late;
    EXPECT_LT(late, bound[i++] * early) << variant << ": early " << early << ", late " << late;
    EXPECT_LT(s.late_pose / s.n_late, 0.25) << variant;
  }
  std::filesystem::remove_all(options.out);
}

// Recorded steps: all up to 100, about 50 per decade after, and the last.
TEST(LgSlamExperiment, RecordedStepsAreLogSpaced) {
  int decade = 0;
  for (std::uint64_t t = 1; t <= 100; ++t) EXPECT_TRUE(lg_slam_recorded_step(t, 5000));
  for (std::uint64_t t = 1000; t < 10000; ++t) decade += lg_slam_recorded_step(t, 20000) ? 1 : 0;
  EXPECT_EQ(decade, 50);
  EXPECT_TRUE(lg_slam_recorded_step(4321, 4321));
  EXPECT_FALSE(lg_slam_recorded_step(4321, 5000));
}

// The gauge: the filter knows every pose exactly (motion noise 0) and sees every landmark through
// noise-free observations shifted by a common d, so it maps each landmark at truth + d. Anchored
// (absolute) errors are |d| for the landmarks; relative ones remove d from the landmarks and the
// pose alike, so the map is exact and the pose is off by -d relative to it.
TEST(LgSlamExperiment, ErrorsRemoveTheCommonOffsetOnlyWhenRelative) {
  LgSlamWorldConfig world;
  LgSlamSimulator sim(world, 1);
  engine::LgSlamConfig config;
  config.landmarks = world.landmarks;
  config.motion_cov.setZero();
  engine::LgSlamFilter filter(config, sim.pose());
  LgSlamErrors none = lg_slam_errors(filter, sim.landmarks(), sim.pose(), true);
  EXPECT_EQ(none.counted, 0u);
  EXPECT_TRUE(std::isnan(none.landmark));

  const Eigen::Vector2d d(0.3, -0.4);
  Eigen::Vector2d u;
  std::vector<engine::LgSlamObservation> observations;
  sim.step(u, observations);
  const Eigen::Vector2d pose_after = sim.pose();
  std::vector<engine::LgSlamObservation> exact;
  for (std::size_t k = 0; k < world.landmarks; ++k) {
    exact.push_back({k, sim.landmarks()[k] - pose_after + d});
  }
  filter.step(pose_after - filter.pose(0), exact);
  const LgSlamErrors absolute = lg_slam_errors(filter, sim.landmarks(), pose_after, false);
  const LgSlamErrors relative = lg_slam_errors(filter, sim.landmarks(), pose_after, true);
  EXPECT_EQ(absolute.counted, world.landmarks);
  EXPECT_NEAR(absolute.landmark, 0.5, 1e-12);
  EXPECT_NEAR(absolute.pose, 0.0, 1e-12);
  EXPECT_NEAR(relative.landmark, 0.0, 1e-12);
  EXPECT_NEAR(relative.pose, 0.5, 1e-12);

  // A known landmark is not counted.
  engine::LgSlamFilter anchored(config, sim.pose());
  anchored.set_known_landmark(0, sim.landmarks()[0]);
  EXPECT_EQ(lg_slam_errors(anchored, sim.landmarks(), sim.pose(), false).counted, 0u);
}

TEST(LgSlamExperiment, RefusesBadOptions) {
  LgSlamExperimentOptions options;
  options.seeds = 0;
  EXPECT_THROW(run_lg_slam_experiment(options), std::invalid_argument);
  options.seeds = 1;
  options.particles = 0;
  EXPECT_THROW(run_lg_slam_experiment(options), std::invalid_argument);
  options.particles = 1;
  options.world.sensor_range = 0.0;
  try {
    run_lg_slam_experiment(options);
    ADD_FAILURE() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("sensor_range"), std::string::npos) << e.what();
  }
  EXPECT_THROW(write_lg_slam_csv("/nonexistent-dir/x/lg_slam.csv", {}), std::runtime_error);
}

}  // namespace
}  // namespace fastslam::tools
