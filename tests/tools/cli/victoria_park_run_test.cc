// End to end on the real Victoria Park data (../shared): `fastslam run --source victoria-park`
// as the command line parses it (the source's defaults included), FastSLAM 1.0, M = 100, ML
// association, one seed. A run is a deterministic function of the seed (and the same for any
// thread count), so the bounds below are the measured values with a margin, not statistics:
// docs/victoria-park.md has the numbers over seeds 1-5. FastSLAM 2.0 with one particle, and
// both versions without odometry too. About 23 s CPU in release;
// labelled "end-to-end", which the sanitizer presets leave out.
#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/shared_data.h"
#include "tests/tools/cli/parsed_run.h"
#include "tools/cli/run_command.h"
#include "tools/datasets/victoria_park.h"

namespace fastslam::tools {
namespace {

nlohmann::json run(const std::string& args, const std::string& name) {
  return testing::parsed_run(args, "vp_" + name);
}

TEST(VictoriaParkRun, FastSlam1WithMaximumLikelihoodMatchesThePaper) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const nlohmann::json m = run("--source victoria-park --data " + shared +
                                   "/data/victoria_park --algorithm fastslam1 --particles 100 "
                                   "--association ml --seed 1",
                               "fs1");
  EXPECT_EQ(m["steps"], 61945);
  EXPECT_EQ(m["scans"], 7249);
  EXPECT_EQ(m["gps_fixes_used"], 4466);
  EXPECT_EQ(m["motion"], "ackermann");
  // The paper: "just over 4 m". Seed 1 measures 3.09 m (seeds 1-5: 3.09 to 4.06 m, mean 3.60;
  // docs/victoria-park.md); the 60 s heading fit gave 6.7 m, table 1's negative information
  // over the whole 70 m 6.2 to 20 m.
  const double rmse = m["gps_rmse_m"].get<double>();
  EXPECT_LT(rmse, 4.5);
  EXPECT_GT(rmse, 1.0);  // GPS itself is off by metres: below this something compares wrongly
  // Negative information keeps the map sane: seed 1 ends with 490 trees (seeds 1-5: 486 to
  // 490); without negative information 630, with table 1's penalty over the whole 70 m 165.
  const int landmarks = m["landmarks"].get<int>();
  EXPECT_GT(landmarks, 250);
  EXPECT_LT(landmarks, 600);
  EXPECT_GT(m["landmarks_removed"].get<int>(), 0);
}

// The paper's section 10.2: FastSLAM 2.0 with a single particle builds a usable map. With the
// source's FastSLAM 2.0 noises (0.5 m, 0.02 rad) seed 1 measures 3.04 m (seeds 1-5: 2.96 to
// 3.88 m); with FastSLAM 1.0's 1.0 m / 0.05 rad it ends 17 to 91 m off.
TEST(VictoriaParkRun, FastSlam2WithOneParticleBuildsAUsableMap) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const nlohmann::json m = run("--source victoria-park --data " + shared +
                                   "/data/victoria_park --algorithm fastslam2 --particles 1 "
                                   "--association ml --seed 1",
                               "fs2");
  EXPECT_EQ(m["particles"], 1);
  EXPECT_LT(m["gps_rmse_m"].get<double>(), 4.5);
  const int landmarks = m["landmarks"].get<int>();
  EXPECT_GT(landmarks, 300);
  EXPECT_LT(landmarks, 900);
}

// FastSLAM 2.0 with 100 particles and odometry takes the source's error correlation (0.89): its
// weights count a scan at (1 - rho) / (1 + rho) of an independent one, as the innovations'
// repetition from scan to scan says (tools/scripts/innovation_correlation.py). Seed 1 measures
// 2.88 m against 7.16 m without it (seeds 1-10: 3.37 against 6.44 m mean; docs/victoria-park.md).
TEST(VictoriaParkRun, FastSlam2WeighsRepeatedErrorsOnce) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const std::string args = "--source victoria-park --data " + shared +
                           "/data/victoria_park --algorithm fastslam2 --association ml --seed 1";
  const nlohmann::json m = run(args, "fs2_100");
  const nlohmann::json independent = run(args + " --error-correlation 0", "fs2_100_independent");
  EXPECT_EQ(m["options"]["error-correlation"],
            VictoriaParkFilterDefaults{}.fastslam2_error_correlation);
  EXPECT_EQ(independent["options"]["error-correlation"], 0.0);
  const double rmse = m["gps_rmse_m"].get<double>();
  EXPECT_LT(rmse, 3.5);
  EXPECT_LT(rmse, 0.6 * independent["gps_rmse_m"].get<double>());
}

// Without odometry (--motion none: the Brownian velocities of eq. 79-81, the rear axle tracked)
// against the same filter with odometry, both at the laser yaw the data gives without GPS
// (tools/scripts/vp_calibrate.py: -1.1 deg), 300 particles without odometry (100 lose seeds). Seed
// 1 measures 7.0 m against 6.0 m (1.17x; seeds 1-10: 7.39 against 6.73 m mean, 1.10x). At the
// nominal yaw 0 the path without odometry comes out rotated by about 3 deg (seeds 1-10: 2.35x);
// docs/victoria-park.md.
TEST(VictoriaParkRun, FastSlam1WithoutOdometryIsWithinOneAndAHalfOfOdometry) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const std::string common = "--source victoria-park --data " + shared +
                             "/data/victoria_park --algorithm fastslam1 --association ml "
                             "--vp-laser-yaw-deg -1.1 --seed 1";
  const nlohmann::json odometry = run(common + " --particles 100", "yaw_odometry");
  const nlohmann::json none = run(common + " --particles 300 --motion none", "yaw_none");
  EXPECT_EQ(odometry["motion"], "ackermann");
  EXPECT_EQ(none["motion"], "none");
  EXPECT_EQ(none["gps_fixes_used"], 4466);
  const double with = odometry["gps_rmse_m"].get<double>();
  const double without = none["gps_rmse_m"].get<double>();
  EXPECT_LT(with, 7.0);
  EXPECT_GT(without, 1.0);
  EXPECT_LT(without, 1.5 * with);
}

// The curvature walk (--motion none-curvature: a standing car cannot turn) at the yaw GPS
// prefers, -0.5 deg, with 100 particles: seed 1 measures 3.9 m, within 1.5x of the odometry
// run's mean there (3.62 m, seeds 1-10). With 100 particles this setting loses seeds 2, 3 and 8
// of 1-10 (11-19 m; none with 300), so this guards the pipeline on a seed that keeps the path.
TEST(VictoriaParkRun, FastSlam1WithTheCurvatureWalk) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const nlohmann::json m = run("--source victoria-park --data " + shared +
                                   "/data/victoria_park --algorithm fastslam1 --particles 100 "
                                   "--association ml --motion none-curvature "
                                   "--vp-laser-yaw-deg -0.5 --seed 1",
                               "none_curvature");
  EXPECT_EQ(m["motion"], "none-curvature");
  const double rmse = m["gps_rmse_m"].get<double>();
  EXPECT_LT(rmse, 1.5 * 3.62);
  EXPECT_GT(rmse, 1.0);
}

// FastSLAM 2.0 without odometry keeps the velocities as a Gaussian given each particle's drawn
// pose (engine/proposal.h draw_state). Seed 1 with 0.7 m / 0.03 rad measures 3.87 m; drawing
// the velocities as well (sessions before 5) gave 6.37 m there and 62 m on seed 3; seeds 1-10
// are in docs/victoria-park.md.
TEST(VictoriaParkRun, FastSlam2WithoutOdometryKeepsTheVelocitiesGaussian) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const nlohmann::json m = run("--source victoria-park --data " + shared +
                                   "/data/victoria_park --algorithm fastslam2 --particles 100 "
                                   "--association ml --motion none --sigma-range 0.7 "
                                   "--sigma-bearing 0.03 --seed 1",
                               "none_fs2");
  EXPECT_EQ(m["motion"], "none");
  const double rmse = m["gps_rmse_m"].get<double>();
  EXPECT_LT(rmse, 5.5);
  EXPECT_GT(rmse, 1.0);
}

// `fastslam convert` writes the data set as a native log whose header names the generic
// Ackermann model with this car's geometry; running that log equals running the data set
// directly, with odometry and without it (which tracks the rear axle at (a, b) from the laser).
TEST(VictoriaParkRun, ConvertedLogRunsLikeTheDataSet) {
  FASTSLAM_REQUIRE_SHARED(shared);
  const std::string log_path = testing::temp_path("vp_converted") + ".log";
  {
    CLI::App app;
    RunOptions o;
    RunWords w;
    add_convert_options(app, o, w);
    app.parse("--source victoria-park --data " + shared + "/data/victoria_park --out " + log_path,
              false);
    finish_run_options(app, w, o);
    ASSERT_EQ(convert_to_log(o), 0);
  }
  std::ifstream in(log_path);
  std::string line;
  while (std::getline(in, line) && line.rfind("motion", 0) != 0) {
  }
  EXPECT_EQ(line, "motion ackermann 3.78 0.5 2.83 0.76");
  // The log source has no data-set presets: give Victoria Park's (VictoriaParkFilterDefaults).
  const VictoriaParkFilterDefaults vp;
  const std::string filter =
      " --algorithm fastslam1 --particles 10 --association ml --seed 3 "
      "--existence-range-margin " +
      std::to_string(vp.existence_range_margin) + " --existence-missed " +
      std::to_string(vp.existence_missed);
  for (const std::string motion : {"odometry", "none"}) {
    SCOPED_TRACE(motion);
    const nlohmann::json direct = run("--source victoria-park --data " + shared +
                                          "/data/victoria_park --motion " + motion + filter,
                                      "direct_" + motion);
    const nlohmann::json logged =
        run("--source log --data " + log_path + " --motion " + motion + filter, "log_" + motion);
    EXPECT_EQ(logged["motion"], motion == "odometry" ? "ackermann" : "none");
    EXPECT_EQ(logged["motion"], direct["motion"]);
    for (const char* key : {"steps", "scans", "landmarks", "gps_fixes_used"}) {
      EXPECT_EQ(logged[key], direct[key]) << key;
    }
    for (const char* key : {"gps_rmse_m", "log_evidence", "final_gps_error_m"}) {
      EXPECT_EQ(logged[key].get<double>(), direct[key].get<double>()) << key;
    }
  }
  std::filesystem::remove(log_path);
}

}  // namespace
}  // namespace fastslam::tools
