// The scaling study: every point runs its updates at the density the world promises, the live
// memory is at least the one-map lower bound and, with shared maps, far below M maps; the JSON
// carries the keys `fastslam bench scaling` promises; bad options are refused.
#include "tools/studies/scaling_study.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <unistd.h>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "memory/landmark_tree.h"
#include "tests/tools/temp_path.h"

namespace fastslam::tools {
namespace {

TEST(ScalingStudy, PointsShareOneMapAndTheJsonHasTheContractedKeys) {
  for (const auto association :
       {engine::Association::kKnown, engine::Association::kMaximumLikelihood}) {
    SCOPED_TRACE(std::string(engine::to_string(association)));
    ScalingOptions o;
    o.landmarks = {1'000, 4'000};
    o.updates = 120;
    o.particles = {20};
    o.threads = {2};
    o.filter.association = association;
    const std::string json = testing::temp_path("scaling") + ".json";
    ASSERT_EQ(run_scaling_command(o, json), 0);
    std::ifstream in(json);
    const nlohmann::json j = nlohmann::json::parse(in);
    ASSERT_EQ(j["points"].size(), 2u);
    for (const auto& p : j["points"]) {
      EXPECT_EQ(p["updates"], 120);
      // About 4 to 6 landmarks in view per scan on average along the first lane.
      EXPECT_GT(p["observations"].get<double>(), 120 * 2.0);
      EXPECT_GT(p["seconds_per_update"].get<double>(), 0.0);
      const auto live = p["live_bytes"].get<double>();
      const auto one_map = p["lower_bound_bytes"].get<double>();
      EXPECT_GE(live, one_map);
      EXPECT_LT(live, 3.0 * one_map) << "20 particles must share one map, not hold 20";
      EXPECT_TRUE(p.contains("seconds_per_phase"));
      EXPECT_TRUE(p.contains("pose_error_m"));
      EXPECT_EQ(p["particles"], 20);
      EXPECT_EQ(p["threads"], 2);
      EXPECT_DOUBLE_EQ(p["seconds_per_particle_update"].get<double>(),
                       p["seconds_per_update"].get<double>() / 20);
    }
    EXPECT_EQ(j["points"][1]["landmarks"], 4000);
    EXPECT_EQ(j["config"]["association"], engine::to_string(association));
    EXPECT_EQ(j["config"]["engine"], "tree");
    std::filesystem::remove(json);
  }
}

// The linear baseline tracks the truth as well as the tree engine (both within a loose bound of
// the truth on a small world), but holds M whole maps where the tree engine holds about one.
TEST(ScalingStudy, LinearBaselineTracksAsWellAndHoldsMMaps) {
  ScalingOptions o;
  o.updates = 150;
  o.filter.particles = 30;
  o.filter.threads = 2;
  o.filter.association = engine::Association::kMaximumLikelihood;
  o.engine = ScalingEngine::kTree;
  const ScalingPoint tree = run_scaling_point(o, 2'000);
  o.engine = ScalingEngine::kLinear;
  const ScalingPoint linear = run_scaling_point(o, 2'000);
  EXPECT_EQ(linear.updates, 150u);
  EXPECT_EQ(linear.observations, tree.observations);  // the same scans
  // About 45 m driven along a lane with the true map as a prior: both stay within 1 m.
  EXPECT_LT(tree.pose_error, 1.0);
  EXPECT_LT(linear.pose_error, 1.0);
  const double one_flat_map = 2'000.0 * sizeof(memory::Landmark);
  EXPECT_EQ(linear.lower_bound_bytes, static_cast<std::int64_t>(one_flat_map));
  EXPECT_GE(static_cast<double>(linear.live_bytes), 0.5 * 30 * one_flat_map);
  EXPECT_LT(static_cast<double>(tree.live_bytes),
            3.0 * static_cast<double>(tree.lower_bound_bytes));
  EXPECT_GT(linear.live_bytes, 5 * tree.live_bytes);
}

TEST(ScalingStudy, LinearBaselineRefusesLargeMapsAndUnsupportedConfigs) {
  ScalingOptions o;
  o.engine = ScalingEngine::kLinear;
  o.updates = 5;
  o.filter.association = engine::Association::kMaximumLikelihood;
  o.linear_max_landmarks = 1'000;
  try {
    run_scaling_point(o, 1'001);
    ADD_FAILURE() << "N above the cap was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("cap of 1000"), std::string::npos) << e.what();
  }
  o.landmarks = {100, 1'001};  // the command checks every N before running any
  EXPECT_THROW(run_scaling_command(o, ""), std::invalid_argument);
  o.filter.algorithm = engine::Algorithm::kFastSlam2;
  EXPECT_THROW(run_scaling_point(o, 100), std::invalid_argument);
}

// One command runs every (N, M, threads) of the lists, N outermost, threads innermost, each
// point `repeats` times reporting the fastest; the CSV has the header and one line per point;
// the results do not depend on the thread count (the same seed gives the same estimate).
TEST(ScalingStudy, ListsMakeOnePointPerCombinationInJsonAndCsv) {
  ScalingOptions o;
  o.landmarks = {500, 2'000};
  o.particles = {1, 16};
  o.threads = {1, 2};
  o.filter.grain = 8;  // let 16 particles split over two threads
  o.updates = 30;
  o.repeats = 2;
  const std::string base = testing::temp_path("scaling_lists");
  ASSERT_EQ(run_scaling_command(o, base + ".json", base + ".csv"), 0);
  std::ifstream in(base + ".json");
  const nlohmann::json j = nlohmann::json::parse(in);
  ASSERT_EQ(j["points"].size(), 8u);
  std::size_t k = 0;
  for (const std::uint64_t n : o.landmarks) {
    for (const unsigned m : o.particles) {
      for (const unsigned t : o.threads) {
        const auto& p = j["points"][k++];
        EXPECT_EQ(p["landmarks"], n);
        EXPECT_EQ(p["particles"], m);
        EXPECT_EQ(p["threads"], t);
        ASSERT_EQ(p["run_seconds"].size(), 2u);
        EXPECT_DOUBLE_EQ(p["seconds"].get<double>(), std::min(p["run_seconds"][0].get<double>(),
                                                              p["run_seconds"][1].get<double>()));
        if (t == 2) {  // same seed, 1 and 2 threads: the same estimate and memory
          const auto& one = j["points"][k - 2];
          EXPECT_EQ(p["pose_error_m"], one["pose_error_m"]);
          EXPECT_EQ(p["live_bytes"], one["live_bytes"]);
        }
      }
    }
  }
  EXPECT_EQ(j["config"]["particles"], nlohmann::json({1, 16}));
  EXPECT_EQ(j["config"]["grain"], 8);
  std::ifstream csv(base + ".csv");
  std::string line;
  std::vector<std::string> lines;
  while (std::getline(csv, line)) lines.push_back(line);
  ASSERT_EQ(lines.size(), 9u);
  EXPECT_EQ(lines[0].rfind("engine,algorithm,association,landmarks,particles,threads,", 0), 0u)
      << lines[0];
  EXPECT_EQ(lines[8].rfind("tree,fastslam1,known,2000,16,2,30,", 0), 0u) << lines[8];
  std::filesystem::remove(base + ".json");
  std::filesystem::remove(base + ".csv");
}

TEST(ScalingStudy, RefusesBadOptions) {
  ScalingOptions o;
  o.updates = 0;
  EXPECT_THROW(run_scaling_point(o, 1000), std::invalid_argument);
  o.updates = 10;
  EXPECT_THROW(run_scaling_point(o, 0), std::invalid_argument);
  o.filter.particles = 0;
  EXPECT_THROW(run_scaling_point(o, 1000), std::invalid_argument);
  ScalingOptions lists;
  lists.landmarks = {100};
  lists.updates = 5;
  lists.particles = {};
  EXPECT_THROW(run_scaling_command(lists, ""), std::invalid_argument);
  lists.particles = {10, 0};  // refused before the first point runs
  EXPECT_THROW(run_scaling_command(lists, ""), std::invalid_argument);
  lists.particles = {10};
  lists.repeats = 0;
  EXPECT_THROW(run_scaling_command(lists, ""), std::invalid_argument);
  lists.repeats = 1;
  lists.engine = ScalingEngine::kLinear;
  lists.threads = {1, 2};  // the baseline has one thread
  EXPECT_THROW(run_scaling_command(lists, ""), std::invalid_argument);
}

}  // namespace
}  // namespace fastslam::tools
