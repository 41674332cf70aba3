// The scaling study: every point runs its updates at the density the world promises, the live
// memory is at least the one-map lower bound and, with shared maps, far below M maps; the JSON
// carries the keys `fastslam bench scaling` promises; bad options are refused.
#include "tools/scaling_study.h"

#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

namespace fastslam::tools {
namespace {

TEST(ScalingStudy, PointsShareOneMapAndTheJsonHasTheContractedKeys) {
  for (const auto association : {engine::Association::kKnown,
                                 engine::Association::kMaximumLikelihood}) {
    SCOPED_TRACE(std::string(engine::to_string(association)));
    ScalingOptions o;
    o.landmarks = {1'000, 4'000};
    o.updates = 120;
    o.filter.particles = 20;
    o.filter.threads = 2;
    o.filter.association = association;
    const std::string json = (std::filesystem::temp_directory_path() /
                              ("fastslam_scaling_" + std::to_string(::getpid()) + ".json"))
                                 .string();
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
    }
    EXPECT_EQ(j["points"][1]["landmarks"], 4000);
    EXPECT_EQ(j["config"]["association"], engine::to_string(association));
    std::filesystem::remove(json);
  }
}

TEST(ScalingStudy, RefusesBadOptions) {
  ScalingOptions o;
  o.updates = 0;
  EXPECT_THROW(run_scaling_point(o, 1000), std::invalid_argument);
  o.updates = 10;
  EXPECT_THROW(run_scaling_point(o, 0), std::invalid_argument);
  o.filter.particles = 0;
  EXPECT_THROW(run_scaling_point(o, 1000), std::invalid_argument);
}

}  // namespace
}  // namespace fastslam::tools
