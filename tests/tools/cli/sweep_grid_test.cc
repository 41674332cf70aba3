#include "tools/cli/sweep_grid.h"

#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/tools/temp_path.h"

namespace fastslam::tools {
namespace {

// A sweep file in a scratch directory, removed with it.
class SweepFile {
 public:
  explicit SweepFile(const std::string& text) : dir_(testing::temp_path("sweep_grid")) {
    std::filesystem::create_directories(dir_);
    std::ofstream(path()) << text;
  }
  ~SweepFile() { std::filesystem::remove_all(dir_); }
  std::string path() const { return dir_ + "/sweep.json"; }
  std::string dir() const { return dir_; }

 private:
  std::string dir_;
};

SweepPlan plan(const std::string& text, std::vector<std::string> args = {},
               std::vector<std::string> grid = {}) {
  const SweepFile file(text);
  return plan_sweep({.config = file.path(),
                     .out = file.dir() + "/out",
                     .grid = std::move(grid),
                     .run_args = std::move(args)});
}

// Sources outermost, then the grid's keys in name order, the last fastest; seeds innermost.
TEST(PlanSweep, CartesianProductNamedByItsValues) {
  const SweepPlan p = plan(R"({
    "base": {"max-steps": 30, "no-plot": true},
    "seeds": "1-2",
    "grid": {"particles": [10, 20], "association": ["ml", "das"]},
    "sources": [{"name": "grid", "world": "grid"}, {"name": "loop", "world": "loop"}]})");
  ASSERT_EQ(p.configurations.size(), 8u);
  ASSERT_EQ(p.runs.size(), 16u);
  EXPECT_EQ(p.seeds, (std::vector<std::uint64_t>{1, 2}));
  EXPECT_EQ(p.configurations[0].name, "grid_association-ml_particles-10");
  EXPECT_EQ(p.configurations[1].name, "grid_association-ml_particles-20");
  EXPECT_EQ(p.configurations[2].name, "grid_association-das_particles-10");
  EXPECT_EQ(p.configurations[7].name, "loop_association-das_particles-20");
  const RunOptions& o = p.configurations[7].options;
  EXPECT_EQ(o.world, "loop");
  EXPECT_EQ(o.association, "das");
  EXPECT_EQ(o.filter.particles, 20u);
  EXPECT_EQ(*o.max_steps, 30u);
  EXPECT_EQ(o.plot, "none");
  EXPECT_FALSE(o.progress);
  EXPECT_EQ(p.configurations[7].axes,
            (nlohmann::json{{"source", "loop"}, {"association", "das"}, {"particles", 20}}));
  EXPECT_EQ(p.runs[3].dir, "grid_association-ml_particles-20/seed-2");
  EXPECT_EQ(p.runs[3].seed, 2u);
  EXPECT_EQ(p.grid["source"], (nlohmann::json{"grid", "loop"}));
}

// Largest first by particles x steps; the plan's order among equals.
TEST(PlanSweep, LargestFirst) {
  const SweepPlan p = plan(R"({"base": {"world": "loop", "no-plot": true}, "seeds": "1-2",
    "grid": {"particles": [10, 30], "max-steps": [50, 20]}})");
  // max-steps-20_particles-10 (200), -20_-30 (600), -50_-10 (500), -50_-30 (1500)
  const std::vector<std::size_t> order = largest_first(p);
  std::vector<std::string> dirs;
  for (std::size_t i : order) dirs.push_back(p.runs[i].dir);
  EXPECT_EQ(dirs, (std::vector<std::string>{
                      "max-steps-50_particles-30/seed-1", "max-steps-50_particles-30/seed-2",
                      "max-steps-20_particles-30/seed-1", "max-steps-20_particles-30/seed-2",
                      "max-steps-50_particles-10/seed-1", "max-steps-50_particles-10/seed-2",
                      "max-steps-20_particles-10/seed-1", "max-steps-20_particles-10/seed-2"}));
}

// No axes: one configuration run into OUT/seed-S; the command line's flags win over "base";
// --grid replaces the file's axis; --seeds the file's seeds.
TEST(PlanSweep, CommandLineFlags) {
  const SweepPlan one =
      plan(R"({"base": {"particles": 7, "world": "loop"}})", {"--particles", "9"});
  ASSERT_EQ(one.runs.size(), 1u);
  EXPECT_EQ(one.runs[0].dir, "seed-1");
  EXPECT_EQ(one.configurations[0].options.filter.particles, 9u);
  const SweepPlan flags = plan(R"({"grid": {"particles": [1, 2, 3]}, "seeds": "5"})",
                               {"--seeds", "3-4", "--world", "loop"}, {"particles=4,8"});
  ASSERT_EQ(flags.configurations.size(), 2u);
  EXPECT_EQ(flags.configurations[1].name, "particles-8");
  EXPECT_EQ(flags.configurations[1].options.filter.particles, 8u);
  EXPECT_EQ(flags.seeds, (std::vector<std::uint64_t>{3, 4}));
}

// A run's identity (what a rerun compares) changes with its seed and its options, not with
// its threads.
TEST(PlanSweep, IdentityOfEachRun) {
  const std::string text = R"({"base": {"world": "loop"}, "seeds": "1-2",
                               "grid": {"particles": [5, 6]}})";
  const SweepPlan a = plan(text, {"--threads", "1"});
  const SweepPlan b = plan(text, {"--threads", "2"});
  ASSERT_EQ(a.runs.size(), 4u);
  for (std::size_t i = 0; i < a.runs.size(); ++i) EXPECT_EQ(a.runs[i].identity, b.runs[i].identity);
  EXPECT_NE(a.runs[0].identity, a.runs[1].identity);  // seeds
  EXPECT_NE(a.runs[0].identity, a.runs[2].identity);  // particles
  const SweepPlan c = plan(text, {"--max-steps", "40"});
  EXPECT_NE(a.runs[0].identity, c.runs[0].identity);
  const RunOptions o = run_options(a, 3, "OUT");
  EXPECT_EQ(o.out, "OUT/particles-6/seed-2");
  EXPECT_EQ(o.filter.seed, 2u);
  const nlohmann::json sweep_run = nlohmann::json::parse(o.sweep_run);
  EXPECT_EQ(sweep_run["identity"], a.runs[3].identity);
  EXPECT_EQ(sweep_run["configuration"], "particles-6");
}

// Every refusal names the file, the place and the key.
TEST(PlanSweep, RefusesBadGridsNamingTheKey) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {R"({"base": {"partcles": 5}})", "base: key 'partcles': unknown option of `fastslam run`"},
      {R"({"grid": {"particles": []}})", "grid: key 'particles': empty axis"},
      {R"({"grid": {"particles": 5}})", "grid: key 'particles': an axis must be an array"},
      {R"({"grid": {"particles": [5, 5]}})", "grid: key 'particles': value 5 is given twice"},
      {R"({"grid": {"particles": [[5]]}})", "values must be numbers, strings or booleans"},
      {R"({"grid": {"particles": [1], "particles": [2]}})", "key 'particles' is repeated"},
      {R"({"base": {"particles": 5}, "grid": {"particles": [1, 2]}})",
       "key 'particles' is in both base and grid"},
      {R"({"bse": {}})", "key 'bse': unknown"},
      {R"({"base": {"seed": 3}})", "base: key 'seed': give the seeds as the file's top-level"},
      {R"({"base": {"trace": "t.csv"}})", "base: key 'trace': not in a sweep"},
      {R"({"grid": {"out": ["a", "b"]}})", "grid: key 'out': not in a sweep"},
      {R"({"seeds": "3-1"})", "key 'seeds': --seeds: '3-1' must be LO-HI"},
      {R"({"grid": {"particles": [0, 5]}})",
       "(configuration particles-0): key 'particles': --particles"},
      {R"({"sources": []})", "key 'sources': empty axis"},
      {R"({"sources": [{"world": "loop"}]})", "sources[0]: key 'name'"},
      {R"({"sources": [{"name": "a"}, {"name": "a"}]})",
       "sources[1]: key 'name': 'a' is given twice"},
      {R"({"base": {"world": "loop"}, "sources": [{"name": "a", "world": "grid"}]})",
       "sources[0]: key 'world' is also in base"},
      {R"({"grid": {"data": ["a b", "a_b"]}})", "get the same directory name"},
      {R"([1, 2])", "expected one JSON object"},
      {R"({"grid": )", "not valid JSON"},
  };
  for (const auto& [text, fragment] : cases) {
    try {
      plan(text);
      ADD_FAILURE() << "accepted: " << text;
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos)
          << text << "\n  gave: " << e.what() << "\n  wanted: " << fragment;
      EXPECT_NE(std::string(e.what()).find("sweep.json"), std::string::npos) << e.what();
    }
  }
  // An axis on the command line and in the grid, and one-run flags.
  EXPECT_THROW(plan(R"({"grid": {"particles": [1, 2]}})", {"--particles", "3"}),
               std::runtime_error);
  EXPECT_THROW(plan("{}", {"--seed", "3"}), std::runtime_error);
  EXPECT_THROW(plan("{}", {"--stream", "-"}), std::runtime_error);
  EXPECT_THROW(plan("{}", {"--no-such-flag"}), std::runtime_error);
  EXPECT_THROW(plan("{}", {}, {"particles"}), std::runtime_error);
}

}  // namespace
}  // namespace fastslam::tools
