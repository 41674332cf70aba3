#include "tools/cli/run_provenance.h"

#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <sys/stat.h>

#include <CLI/CLI.hpp>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/tools/temp_path.h"
#include "tools/cli/build_info.h"
#include "tools/cli/command_line.h"
#include "tools/io/sha256.h"

namespace fastslam::tools {
namespace {

// The options object of `fastslam run ARGS` with the run's own resolution of what the source
// decides stood in for by fixed values (a log header's models, radius 5, delta 10).
nlohmann::json options_of(const std::string& args, const std::string& config = "") {
  CLI::App app;
  RunOptions o;
  RunWords w;
  add_run_options(app, o, w);
  app.parse(args, false);
  if (!config.empty()) apply_json_config(app, config);
  finish_run_options(app, w, o);
  o.match_radius = o.match_radius.value_or(5.0);
  o.rpe_delta = o.rpe_delta.value_or(10.0);
  return resolved_options_json(o, filter_config(o, LogHeader{}), "ml");
}

TEST(RunProvenance, EveryOptionOfRunHasAKey) {
  CLI::App app;
  RunOptions o;
  RunWords w;
  add_run_options(app, o, w);
  const nlohmann::json options = options_of("");
  // --config is recorded among the inputs, with its hash; a resumed run's metrics equal the
  // uninterrupted run's, so --resume is not recorded.
  const std::set<std::string> not_options = {"--help", "--config", "--resume"};
  std::size_t checked = 0;
  for (const CLI::Option* option : app.get_options()) {
    for (const std::string& name : option->get_lnames()) {
      if (not_options.contains("--" + name)) continue;
      EXPECT_TRUE(options.contains(name)) << "--" << name << " is missing from \"options\"";
      ++checked;
    }
  }
  EXPECT_GT(checked, 60U);
  EXPECT_EQ(options.size(), checked) << options.dump();
}

// The options object is a --config file that repeats the run: read back, it gives itself.
TEST(RunProvenance, TheOptionsObjectReadBackAsAConfigGivesItself) {
  const std::string path = testing::temp_path("provenance_config") + ".json";
  const nlohmann::json first = options_of(
      "--world loop --particles 7 --seed 12 --max-steps 40 --sigma-range 0.3 --association ml "
      "--vp-max-diameter 0.8 --no-plot --resample every --trace t.csv --max-memory 1.5G");
  EXPECT_EQ(first["particles"], 7);
  EXPECT_EQ(first["max-memory"], std::uint64_t{3} << 29);  // bytes, read back as they are
  EXPECT_EQ(first["max-steps"], 40);
  EXPECT_EQ(first["max-seconds"], nullptr);
  EXPECT_EQ(options_of("")["max-memory"], 0);  // the machine's
  EXPECT_EQ(first["sigma-range"], 0.3);
  EXPECT_EQ(first["spacing"], kDefaultLoopSpacing);
  std::ofstream(path) << first.dump();
  const nlohmann::json second = options_of("", path);
  EXPECT_EQ(second, first) << "first:  " << first.dump() << "\nsecond: " << second.dump();
  std::filesystem::remove(path);
}

TEST(RunProvenance, InputFilesAreHashedExceptStandardInputPipesAndDevices) {
  const std::string dir = testing::temp_path("provenance_inputs");
  std::filesystem::create_directories(dir + "/sub");
  std::ofstream(dir + "/b.txt") << "second";
  std::ofstream(dir + "/sub/a.txt") << "abc";
  RunOptions o;
  o.source = "victoria-park";
  o.data = dir;
  nlohmann::json files = input_files_json(o);
  ASSERT_EQ(files.size(), 2U) << files.dump();
  EXPECT_EQ(files[0]["path"], dir + "/b.txt");
  EXPECT_EQ(files[0]["sha256"], sha256_hex("second"));
  EXPECT_EQ(files[1]["path"], dir + "/sub/a.txt");
  EXPECT_EQ(files[1]["bytes"], 3);
  EXPECT_EQ(files[1]["sha256"],
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");

  o.source = "log";
  o.data = "-";
  files = input_files_json(o);
  ASSERT_EQ(files.size(), 1U);
  EXPECT_EQ(files[0]["sha256"], nullptr);
  EXPECT_EQ(files[0]["not_hashed"], "standard input is read once, by the run");

  // A pipe would be drained by hashing and /dev/zero never ends: neither is read.
  const std::string fifo = dir + "/fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  for (const std::string& path : {fifo, std::string("/dev/zero")}) {
    o.data = path;
    files = input_files_json(o);
    ASSERT_EQ(files.size(), 1U);
    EXPECT_EQ(files[0]["sha256"], nullptr) << path;
    EXPECT_FALSE(files[0].contains("bytes")) << path;
  }

  // A simulated source reads its CSVs, not --data; --config is an input of any run.
  o = RunOptions{};
  o.data = dir;  // not read by the simulator
  o.landmarks_csv = dir + "/b.txt";
  o.config = dir + "/sub/a.txt";
  files = input_files_json(o);
  ASSERT_EQ(files.size(), 2U) << files.dump();
  EXPECT_EQ(files[0]["option"], "--config");
  EXPECT_EQ(files[1]["option"], "--landmarks-csv");
  std::filesystem::remove_all(dir);
}

TEST(RunProvenance, BuildFactsAreFilled) {
  const BuildInfo b = build_info();
  EXPECT_FALSE(b.version.empty());
  EXPECT_TRUE(b.commit == "unknown" || b.commit.size() == 40) << b.commit;
  EXPECT_FALSE(b.compiler.empty());
  EXPECT_TRUE(b.simd == "native" || b.simd == "baseline" || b.simd == "avx2" ||
              b.simd == "avx512")
      << b.simd;
  const std::string text = version_text();
  EXPECT_EQ(text.rfind("fastslam " + b.version + "\ncommit " + b.commit, 0), 0U) << text;
}

}  // namespace
}  // namespace fastslam::tools
