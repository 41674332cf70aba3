// The built-in stress run (`fastslam run` with no option: a 10^5-landmark grid driven by a
// lawnmower route, FastSLAM 1.0, M = 100) stays bounded: its path's shape within metres of the
// truth and far inside dead reckoning's error. Over seeds 1-10 it measured 0.66 m median and
// 1.26 m worst aligned, 8.6 m mean raw, against dead reckoning's 88 m mean (docs/results.md);
// seed 1 here. About 8 s in release; labelled "end-to-end", which the sanitizer presets leave
// out.
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/tools/cli/parsed_run.h"

namespace fastslam::tools {
namespace {

TEST(StressRun, TheDefaultRunStaysBounded) {
  const nlohmann::json m = testing::parsed_run("--seed 1", "stress_default");
  EXPECT_EQ(m["landmarks"], 100000);
  EXPECT_EQ(m["association"], "known");
  EXPECT_LT(m["pose_rmse_aligned_m"].get<double>(), 2.0);
  EXPECT_LT(m["pose_rmse_m"].get<double>(), 25.0);
  EXPECT_LT(m["pose_rmse_m"].get<double>(), 0.5 * m["dead_reckoning"]["pose_rmse_m"].get<double>());
  EXPECT_LT(m["gospa_aligned_m"].get<double>(), m["gospa_m"].get<double>());
}

}  // namespace
}  // namespace fastslam::tools
