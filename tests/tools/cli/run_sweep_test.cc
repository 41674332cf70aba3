#include "tools/cli/run_sweep.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/tools/temp_path.h"

namespace fastslam::tools {
namespace {

TEST(ParseSeeds, RangesAndListsInTheOrderGiven) {
  EXPECT_EQ(parse_seeds("1-4"), (std::vector<std::uint64_t>{1, 2, 3, 4}));
  EXPECT_EQ(parse_seeds("7"), (std::vector<std::uint64_t>{7}));
  EXPECT_EQ(parse_seeds("9,2-3,5"), (std::vector<std::uint64_t>{9, 2, 3, 5}));
  for (const char* bad : {"", "x", "1,", "3-1", "1-", "-2", "1,1", "1-3,2", "1.5"}) {
    EXPECT_THROW(parse_seeds(bad), std::invalid_argument) << bad;
  }
}

// Mean, median, extremes and the sample standard deviation by hand; nested objects flattened;
// booleans counted; keys missing from some seeds summarised over the others.
TEST(SummariseSeeds, StatisticsOfEveryNumber) {
  const std::vector<nlohmann::json> runs = {
      {{"e", 1.0}, {"dr", {{"e", 10.0}}}, {"bad", false}, {"name", "x"}},
      {{"e", 4.0}, {"dr", {{"e", 20.0}}}, {"bad", true}},
      {{"e", 7.0}, {"dr", {{"e", 60.0}}}, {"bad", true}, {"only", 2.0}}};
  const nlohmann::json s = summarise_seeds(runs);
  EXPECT_EQ(s["e"]["mean"], 4.0);
  EXPECT_EQ(s["e"]["median"], 4.0);
  EXPECT_EQ(s["e"]["min"], 1.0);
  EXPECT_EQ(s["e"]["max"], 7.0);
  EXPECT_DOUBLE_EQ(s["e"]["stdev"].get<double>(), 3.0);  // sqrt((9 + 0 + 9) / 2)
  EXPECT_EQ(s["dr.e"]["median"], 20.0);
  EXPECT_DOUBLE_EQ(s["dr.e"]["mean"].get<double>(), 30.0);
  EXPECT_EQ(s["bad"]["true"], 2);
  EXPECT_EQ(s["only"]["seeds"], 1);
  EXPECT_FALSE(s.contains("name"));
  const nlohmann::json even = summarise_seeds({{{"e", 1.0}}, {{"e", 2.0}}});
  EXPECT_EQ(even["e"]["median"], 1.5);
}

// Each seed of a sweep is the single run with that seed, bit for bit, and the files hold them.
TEST(RunSweep, EverySeedIsItsOwnRunAndTheSummaryTheirs) {
  RunOptions o;
  o.progress = false;
  o.plot_script.clear();
  o.world = "loop";
  o.loop_length = 300.0;
  o.sim.loops = 1;
  o.filter.particles = 8;
  o.seeds = {4, 2, 9};
  o.out = testing::temp_path("sweep");
  ASSERT_EQ(run_sweep(o), 0);
  std::ifstream in(o.out + "/sweep.json");
  const nlohmann::json sweep = nlohmann::json::parse(in);
  ASSERT_EQ(sweep["per_seed"].size(), 3u);
  double sum = 0.0;
  for (std::size_t i = 0; i < 3; ++i) {
    RunOptions single = o;
    single.seeds.clear();
    single.filter.seed = o.seeds[i];
    single.out.clear();
    const nlohmann::json alone = run_once(single);
    EXPECT_EQ(sweep["per_seed"][i]["seed"], o.seeds[i]);
    EXPECT_EQ(sweep["per_seed"][i]["pose_rmse_m"], alone["pose_rmse_m"]);
    EXPECT_TRUE(
        std::filesystem::exists(o.out + "/seed-" + std::to_string(o.seeds[i]) + "/metrics.json"));
    sum += alone["pose_rmse_m"].get<double>();
  }
  EXPECT_DOUBLE_EQ(sweep["summary"]["pose_rmse_m"]["mean"].get<double>(), sum / 3);
  std::ifstream csv(o.out + "/sweep.csv");
  std::size_t lines = 0;
  for (std::string line; std::getline(csv, line);) ++lines;
  EXPECT_EQ(lines, 4u);
  std::filesystem::remove_all(o.out);
}

}  // namespace
}  // namespace fastslam::tools
