#include "tools/cli/command_line.h"

#include <filesystem>
#include <fstream>
#include <numbers>
#include <string>
#include <utility>
#include <vector>
#include <unistd.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace fastslam::tools {
namespace {

class CommandLine : public ::testing::Test {
 protected:
  void SetUp() override {
    path_ = (std::filesystem::temp_directory_path() /
             ("fastslam_config_test_" + std::to_string(::getpid()) + ".json"))
                .string();
  }
  void TearDown() override { std::filesystem::remove(path_); }

  // Parses `args` for `fastslam run` with `json` as the config file; returns the options.
  RunOptions run(const std::string& json, const std::string& args) {
    std::ofstream(path_) << json;
    CLI::App app;
    RunOptions o;
    RunWords w;
    add_run_options(app, o, w);
    app.parse(args + " --config " + path_, false);
    apply_json_config(app, w.config);
    finish_run_options(app, w, o);
    return o;
  }
  std::string error_of(const std::string& json, const std::string& args = "") {
    try {
      run(json, args);
    } catch (const std::exception& e) {
      return e.what();
    }
    return "(no error)";
  }
  std::string path_;
};

TEST_F(CommandLine, ConfigSetsWhatFlagsSetAndFlagsWin) {
  const RunOptions o = run(R"({"particles": 42, "seed": 9, "algorithm": "fastslam2",
                               "world": "loop", "loop-length": 750.5, "no-progress": true,
                               "sigma-range": 0.25, "resample": "every", "source": "log",
                               "data": "x.log", "loops": 3})",
                           "--particles 7 --world grid");
  EXPECT_EQ(o.filter.particles, 7u);  // the flag wins
  EXPECT_EQ(o.world, "grid");         // the flag wins
  EXPECT_EQ(o.filter.seed, 9u);
  EXPECT_EQ(o.filter.algorithm, engine::Algorithm::kFastSlam2);
  EXPECT_EQ(o.loop_length, 750.5);
  EXPECT_FALSE(o.progress);
  ASSERT_TRUE(o.model.sigma_range.has_value());
  EXPECT_EQ(*o.model.sigma_range, 0.25);
  EXPECT_FALSE(o.model.sigma_bearing.has_value());  // not given anywhere: the source's
  EXPECT_EQ(o.filter.resample.when, parallel::ResamplePolicy::When::kEveryStep);
  EXPECT_EQ(o.source, "log");
  EXPECT_EQ(o.data, "x.log");
  EXPECT_EQ(o.sim.loops, 3);
}

TEST_F(CommandLine, WithoutConfigTheDefaultsStand) {
  const RunOptions o = run("{}", "--sigma-u1 0.1");
  EXPECT_EQ(o.filter.particles, 100u);
  EXPECT_TRUE(o.progress);
  EXPECT_EQ(o.sim.loops, 1);
  // The built-in stress run: a grid of 10^5 landmarks, FastSLAM 1.0, auto association, the grid's
  // spacing and scan period (resolved by the run, tools/cli/run_command.h).
  EXPECT_EQ(o.source, "sim");
  EXPECT_EQ(o.world, "grid");
  EXPECT_TRUE(o.landmarks_csv.empty());
  EXPECT_EQ(o.landmarks, 100'000u);
  EXPECT_FALSE(o.spacing.has_value());
  EXPECT_FALSE(o.scan_period.has_value());
  EXPECT_EQ(o.sim.dt_observe, SimConfig{}.dt_observe);  // Bailey's, for CSV worlds
  EXPECT_EQ(o.filter.algorithm, engine::Algorithm::kFastSlam1);
  EXPECT_EQ(o.association, "auto");  // known on the grid: every detection has its id
  EXPECT_FALSE(o.model.sigma_range.has_value());
  ASSERT_TRUE(o.model.sigma_control1.has_value());
  EXPECT_EQ(*o.model.sigma_control1, 0.1);
}

TEST_F(CommandLine, SeedsAndBudgetsAreSetOnlyWhenGiven) {
  RunOptions o = run("{}", "--seeds 1-3,7 --max-steps 50 --rpe-delta 2");
  EXPECT_EQ(o.seeds, (std::vector<std::uint64_t>{1, 2, 3, 7}));
  ASSERT_TRUE(o.max_steps.has_value());
  EXPECT_EQ(*o.max_steps, 50u);
  EXPECT_FALSE(o.max_seconds.has_value());
  ASSERT_TRUE(o.rpe_delta.has_value());
  EXPECT_EQ(*o.rpe_delta, 2.0);
  EXPECT_FALSE(o.match_radius.has_value());  // the source's
  o = run("{}", "");
  EXPECT_TRUE(o.seeds.empty());
  EXPECT_FALSE(o.max_steps.has_value());
}

TEST_F(CommandLine, MaxMemoryTakesASizeFromTheFlagOrTheConfig) {
  EXPECT_EQ(run("{}", "").max_memory, 0u);  // the machine's
  EXPECT_EQ(run("{}", "--max-memory 4G").max_memory, std::uint64_t{4} << 30);
  EXPECT_EQ(run(R"({"max-memory": "512M"})", "").max_memory, std::uint64_t{512} << 20);
  EXPECT_EQ(run(R"({"max-memory": 1000})", "").max_memory, 1000u);
  EXPECT_EQ(run(R"({"max-memory": "512M"})", "--max-memory 1K").max_memory, 1024u);
  const std::string e = error_of("{}", "--max-memory 4X");
  EXPECT_NE(e.find("--max-memory: '4X' is not a size (unknown unit)"), std::string::npos) << e;
  EXPECT_NE(error_of(R"({"max-memory": "-1"})").find("key 'max-memory'"), std::string::npos);
}

TEST_F(CommandLine, SpacingAndScanPeriodAreSetOnlyWhenGiven) {
  RunOptions o = run(R"({"spacing": 7.5})", "--scan-period 0.4");
  ASSERT_TRUE(o.spacing.has_value());
  EXPECT_EQ(*o.spacing, 7.5);
  ASSERT_TRUE(o.scan_period.has_value());
  EXPECT_EQ(*o.scan_period, 0.4);
  o = run(R"({"scan-period": 2})", "--spacing 4");
  EXPECT_EQ(o.spacing.value_or(0), 4.0);
  EXPECT_EQ(o.scan_period.value_or(0), 2.0);
  EXPECT_NE(error_of("{}", "--scan-period 0").find("--scan-period"), std::string::npos);
  EXPECT_NE(error_of("{}", "--spacing -1").find("--spacing"), std::string::npos);
}

TEST_F(CommandLine, ThreadsGrainAndSplit) {
  RunOptions o = run(R"({"split-seconds": 0})", "--threads 2 --grain 16");
  EXPECT_EQ(o.filter.threads, 2u);
  EXPECT_EQ(o.filter.grain, 16u);
  EXPECT_EQ(o.filter.split_seconds, 0.0);
  o = run("{}", "");
  EXPECT_EQ(o.filter.split_seconds, engine::FilterConfig{}.split_seconds);
  EXPECT_NE(error_of("{}", "--split-seconds -1").find("--split-seconds"), std::string::npos);
}

// Nothing but white space may follow the object: not a NUL byte (which the parser would take
// for the end of the text), not another word.
TEST_F(CommandLine, RefusesAnythingAfterTheObject) {
  std::string e = error_of(std::string("{\"particles\": 10}\n\0{\"seed\": 3}", 30));
  EXPECT_NE(e.find(path_ + ": byte 19: a NUL byte after the JSON object"), std::string::npos) << e;
  e = error_of(std::string("{\"particles\": 10}\0", 18));
  EXPECT_NE(e.find(path_ + ": byte 18: a NUL byte"), std::string::npos) << e;
  e = error_of("{\"particles\": 10} x");
  EXPECT_NE(e.find(path_ + ": not valid JSON: "), std::string::npos) << e;
  EXPECT_NE(e.find("line 1, column 19"), std::string::npos) << e;
  EXPECT_EQ(run("{\"particles\": 10}\n \t\r\n", "").filter.particles, 10u);
}

TEST_F(CommandLine, RefusesUnknownKeysAndBadValuesNamingTheKey) {
  std::string e = error_of(R"({"particles": 10, "partcles": 5})");
  EXPECT_NE(e.find(path_ + ": key 'partcles': unknown option"), std::string::npos) << e;
  e = error_of(R"({"config": "other.json"})");
  EXPECT_NE(e.find("key 'config': unknown option"), std::string::npos) << e;
  e = error_of(R"({"particles": 0})");
  EXPECT_NE(e.find("key 'particles':"), std::string::npos) << e;
  e = error_of(R"({"world": "moon"})");
  EXPECT_NE(e.find("key 'world':"), std::string::npos) << e;
  e = error_of(R"({"particles": "many"})");
  EXPECT_NE(e.find("key 'particles':"), std::string::npos) << e;
  e = error_of(R"({"spacing": [1, 2]})");
  EXPECT_NE(e.find("key 'spacing': value must be a number, a string or a boolean"),
            std::string::npos)
      << e;
  e = error_of(R"([1, 2])");
  EXPECT_NE(e.find(": expected one JSON object"), std::string::npos) << e;
  e = error_of(R"({"particles": 10,)");
  EXPECT_NE(e.find(": not valid JSON"), std::string::npos) << e;
}

// CLI11 alone clamps 2^64 to 2^64 - 1 and wraps -1 round to it for unsigned options.
TEST_F(CommandLine, IntegersOutOfRangeAreRefusedNotClampedOrWrapped) {
  EXPECT_EQ(run("{}", "--seed 18446744073709551615").filter.seed, 18446744073709551615ULL);
  for (const auto& [args, expected] : std::vector<std::pair<std::string, std::string>>{
           {"--seed 18446744073709551616",
            "--seed: '18446744073709551616' is out of range (0 to 18446744073709551615)"},
           {"--seed -1", "--seed: '-1' is out of range (0 to 18446744073709551615)"},
           {"--seed 0x10", "--seed: '0x10' is not a decimal integer"},
           {"--seed 1e3", "--seed: '1e3' is not a decimal integer"},
           {"--particles 4294967296", "--particles: '4294967296' is out of range"},
           {"--threads -2", "--threads: '-2' is out of range"},
           {"--max-steps 99999999999999999999", "is out of range"},
           {"--loops 2147483648", "--loops: '2147483648' is out of range"},
           {"--seed " + std::string(200, '9'), "'" + std::string(80, '9') + "... (200 bytes)'"},
       }) {
    const std::string e = error_of("{}", args);
    EXPECT_NE(e.find(expected), std::string::npos) << args << ": " << e;
    EXPECT_LT(e.size(), 200U) << e;
  }
  const std::string e = error_of(R"({"seed": -1})");
  EXPECT_NE(e.find("key 'seed': --seed: '-1' is out of range"), std::string::npos) << e;
}

// CLI11's double ranges let NaN through, print their bound 2^1024 in full digits and quote a
// value of any length; these are refused briefly instead.
TEST_F(CommandLine, RealsAreFiniteDecimalsWithinTheirRange) {
  EXPECT_EQ(run("{}", "--max-seconds 1e-3").max_seconds.value(), 1e-3);
  EXPECT_EQ(run("{}", "--sigma-u0 0").model.sigma_control0.value(), 0.0);
  EXPECT_EQ(run("{}", "--log-p0 -12.5").filter.log_new_landmark, -12.5);
  for (const auto& [args, expected] : std::vector<std::pair<std::string, std::string>>{
           {"--max-seconds nan", "--max-seconds: 'nan' is not a finite number"},
           {"--max-seconds inf", "--max-seconds: 'inf' is not a finite number"},
           {"--max-seconds -1", "--max-seconds: '-1' must be > 0"},
           {"--max-seconds 0", "--max-seconds: '0' must be > 0"},
           {"--max-seconds 0x10", "--max-seconds: '0x10' is not a number"},
           {"--max-seconds 1e400", "--max-seconds: '1e400' is out of a double's range"},
           {"--sigma-u0 -0.5", "--sigma-u0: '-0.5' must be >= 0"},
           {"--clutter 1001", "--clutter: '1001' is not in [0, 1000]"},
           {"--neff-fraction nan", "--neff-fraction: 'nan' is not a finite number"},
           {"--scan-period 0", "--scan-period: '0' is not in [0.001, 3600]"},
           {"--log-p0 nan", "--log-p0: 'nan' is not a finite number"},
           {"--initial-heading-deg -inf", "--initial-heading-deg: '-inf' is not a finite number"},
           {"--spacing " + std::string(400, '9'),
            "--spacing: '" + std::string(80, '9') + "... (400 bytes)' is out of a double's range"},
       }) {
    const std::string e = error_of("{}", args);
    EXPECT_NE(e.find(expected), std::string::npos) << args << ": " << e;
    EXPECT_LT(e.size(), 200U) << e;
  }
  const std::string e = error_of(R"({"max-seconds": "nan"})");
  EXPECT_NE(e.find("key 'max-seconds': --max-seconds: 'nan' is not a finite number"),
            std::string::npos)
      << e;
}

TEST_F(CommandLine, RepeatedConfigKeysEmptyOutAndTooManyThreadsAreRefused) {
  std::string e = error_of(R"({"seed": 1, "particles": 5, "seed": 2})");
  EXPECT_NE(e.find(path_ + ": key 'seed' is repeated: give each option once"), std::string::npos)
      << e;
  e = error_of(R"({"out": ""})");  // the command line's --out "" is the CLI test's
  EXPECT_NE(e.find("--out \"\" names no path"), std::string::npos) << e;
  const unsigned limit = max_startable_threads();
  EXPECT_GE(limit, 1U);
  EXPECT_EQ(run("{}", "--threads " + std::to_string(limit)).filter.threads, limit);
  e = error_of("{}", "--threads " + std::to_string(limit + 1));
  EXPECT_NE(e.find("--threads " + std::to_string(limit + 1) +
                   ": more than this process can usefully start (" + std::to_string(limit)),
            std::string::npos)
      << e;
}

// The Python module's keyword arguments: a JSON object in memory, read as a config file is.
TEST_F(CommandLine, AJsonObjectInMemoryActsAsAConfigFile) {
  CLI::App app;
  RunOptions o;
  RunWords w;
  add_run_options(app, o, w);
  app.parse("--seed 4", false);
  apply_json_config(app,
                    nlohmann::json{{"particles", 12},
                                   {"seed", 9},
                                   {"no-plot", true},
                                   {"no-progress", false},
                                   {"sigma-range", 0.5}},
                    "fastslam.run");
  finish_run_options(app, w, o);
  EXPECT_EQ(o.filter.particles, 12u);
  EXPECT_EQ(o.filter.seed, 4u);  // given on the command line: it wins
  EXPECT_EQ(o.plot, "none");
  EXPECT_TRUE(o.progress);
  ASSERT_TRUE(o.model.sigma_range.has_value());
  EXPECT_EQ(*o.model.sigma_range, 0.5);
  try {
    apply_json_config(app, nlohmann::json{{"partcles", 5}}, "fastslam.run");
    ADD_FAILURE() << "an unknown key was accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("fastslam.run: key 'partcles': unknown option"),
              std::string::npos)
        << e.what();
  }
}

// The simulator's true noises and the trace are plain options; the filter's noise overrides stay
// unset, so the filter takes the simulator's noises from the source's header.
TEST_F(CommandLine, SimulatorNoiseAndTraceOptions) {
  RunOptions o = run(R"({"sim-sigma-range": 0.05, "trace-every": 4})",
                     "--sim-sigma-speed 0.6 --sim-sigma-steer 0.1 --sim-sigma-bearing 0.02 "
                     "--trace t.csv");
  EXPECT_EQ(o.sim.sigma_v, 0.6);
  EXPECT_EQ(o.sim.sigma_steer, 0.1);
  EXPECT_EQ(o.sim.sigma_range, 0.05);
  EXPECT_EQ(o.sim.sigma_bearing, 0.02);
  EXPECT_FALSE(o.model.sigma_range.has_value());
  EXPECT_FALSE(o.model.sigma_control0.has_value());
  EXPECT_EQ(o.trace, "t.csv");
  EXPECT_EQ(o.trace_every, 4u);
  o = run("{}", "");
  EXPECT_EQ(o.sim.sigma_v, SimConfig{}.sigma_v);
  EXPECT_TRUE(o.trace.empty());
  EXPECT_EQ(o.trace_every, 1u);
  EXPECT_NE(error_of("{}", "--sim-sigma-speed -1").find("sim-sigma-speed"), std::string::npos);
  EXPECT_NE(error_of("{}", "--sim-sigma-range 0").find("sim-sigma-range"), std::string::npos);
  EXPECT_NE(error_of("{}", "--trace-every 0").find("trace-every"), std::string::npos);
}

// --source victoria-park brings its negative-information preset and FastSLAM 2.0's noises and
// error correlation (tools/datasets/victoria_park.h) for the options not given; a flag or a
// config key still wins; other sources keep the engine's.
TEST_F(CommandLine, VictoriaParkSourceSetsItsPresetUnlessGiven) {
  const VictoriaParkFilterDefaults vp;
  const engine::ExistenceConfig engine_defaults;
  RunOptions o = run("{}", "--source victoria-park");
  EXPECT_EQ(o.filter.existence.range_margin, vp.existence_range_margin);
  EXPECT_EQ(o.filter.existence.missed, vp.existence_missed);
  EXPECT_NE(vp.existence_range_margin, engine_defaults.range_margin);  // the test can fail
  o = run(R"({"existence-range-margin": 2.5})", "--source victoria-park --existence-missed 1");
  EXPECT_EQ(o.filter.existence.range_margin, 2.5);
  EXPECT_EQ(o.filter.existence.missed, 1.0);
  EXPECT_FALSE(o.model.sigma_range.has_value());  // FastSLAM 1.0: the header's noises
  o = run("{}", "--source victoria-park --algorithm fastslam2 --sigma-range 0.7");
  EXPECT_EQ(*o.model.sigma_range, 0.7);
  EXPECT_EQ(*o.model.sigma_bearing, vp.fastslam2_sigma_bearing);
  EXPECT_EQ(o.filter.error_correlation, vp.fastslam2_error_correlation);
  EXPECT_EQ(run("{}", "--source victoria-park").filter.error_correlation, 0.0);  // FS1
  // With odometry only; a flag or a config key wins.
  EXPECT_EQ(run("{}", "--source victoria-park --algorithm fastslam2 --motion none")
                .filter.error_correlation,
            0.0);
  EXPECT_EQ(run("{}", "--source victoria-park --algorithm fastslam2 --error-correlation 0.5")
                .filter.error_correlation,
            0.5);
  EXPECT_EQ(run(R"({"error-correlation": 0})", "--source victoria-park --algorithm fastslam2")
                .filter.error_correlation,
            0.0);
  EXPECT_NE(error_of("{}", "--error-correlation 1").find("error-correlation"), std::string::npos);
  o = run("{}", "--source sim --algorithm fastslam2");
  EXPECT_FALSE(o.model.sigma_bearing.has_value());
  EXPECT_EQ(o.filter.error_correlation, 0.0);
  EXPECT_EQ(o.filter.existence.range_margin, engine_defaults.range_margin);
  EXPECT_EQ(o.filter.existence.missed, engine_defaults.missed);
}

// `fastslam run --out` draws map.svg unless --plot says png or none; --no-plot is --plot none
// (tools/cli/run_command.h).
TEST_F(CommandLine, PlotIsSvgUnlessToldOtherwise) {
  RunOptions o = run("{}", "");
  EXPECT_EQ(o.plot, "svg");
  EXPECT_EQ(o.plot_script, default_plot_script());
  EXPECT_NE(o.plot_script.find("plot_run.py"), std::string::npos);
  EXPECT_EQ(run("{}", "--plot png").plot, "png");
  EXPECT_EQ(run("{}", "--plot none").plot, "none");
  EXPECT_EQ(run("{}", "--no-plot").plot, "none");
  EXPECT_EQ(run(R"({"no-plot": true})", "").plot, "none");
  EXPECT_EQ(run(R"({"no-plot": false})", "").plot, "svg");
  EXPECT_EQ(run(R"({"plot": "png"})", "").plot, "png");
  // The command line wins over the file's other spelling too.
  EXPECT_EQ(run(R"({"no-plot": true})", "--plot png").plot, "png");
  EXPECT_EQ(run(R"({"plot": "png"})", "--no-plot").plot, "none");
  // A metrics.json's options say both, in agreement.
  EXPECT_EQ(run(R"({"no-plot": true, "plot": "none"})", "").plot, "none");
  EXPECT_EQ(run(R"({"no-plot": false, "plot": "png"})", "").plot, "png");
  std::string e = error_of(R"({"no-plot": true, "plot": "png"})");
  EXPECT_NE(e.find("--no-plot and --plot png contradict"), std::string::npos) << e;
  e = error_of("{}", "--plot png --no-plot");
  EXPECT_NE(e.find("excludes"), std::string::npos) << e;
  e = error_of("{}", "--plot jpg");
  EXPECT_NE(e.find("jpg"), std::string::npos) << e;
}

TEST_F(CommandLine, MotionNoneAndTheStartHeading) {
  RunOptions o = run("{}", "");
  EXPECT_EQ(o.motion, "odometry");
  EXPECT_FALSE(o.initial_heading.has_value());
  o = run(R"({"motion": "none"})", "--initial-heading-deg 90 --heading-fit-seconds 12");
  EXPECT_EQ(o.motion, "none");
  ASSERT_TRUE(o.initial_heading.has_value());
  EXPECT_DOUBLE_EQ(*o.initial_heading, std::numbers::pi / 2);
  EXPECT_EQ(o.victoria_park.heading_fit_seconds, 12.0);
  EXPECT_EQ(run("{}", "--motion none-curvature").motion, "none-curvature");
  EXPECT_NE(error_of("{}", "--motion bogus").find("--motion"), std::string::npos);
  EXPECT_NE(error_of("{}", "--heading-fit-seconds 0").find("--heading-fit-seconds"),
            std::string::npos);
}

// The Victoria Park gate: metres and degrees on the command line, the reader's defaults unless
// given, config keys as for every flag, bad values refused naming the flag.
TEST_F(CommandLine, VictoriaParkGateFlags) {
  const VictoriaParkGate defaults;
  RunOptions o = run("{}", "");
  EXPECT_EQ(o.victoria_park.gate.min_range, defaults.min_range);
  EXPECT_EQ(o.victoria_park.gate.max_range, defaults.max_range);
  EXPECT_EQ(o.victoria_park.gate.min_bearing, defaults.min_bearing);
  EXPECT_EQ(o.victoria_park.gate.max_bearing, defaults.max_bearing);
  EXPECT_EQ(o.victoria_park.gate.max_diameter, defaults.max_diameter);
  o = run(R"({"vp-max-range": 40, "vp-min-bearing-deg": -45})",
          "--vp-min-range 2 --vp-max-bearing-deg 60 --vp-max-diameter 0.9");
  EXPECT_EQ(o.victoria_park.gate.min_range, 2.0);
  EXPECT_EQ(o.victoria_park.gate.max_range, 40.0);
  EXPECT_DOUBLE_EQ(o.victoria_park.gate.min_bearing, -std::numbers::pi / 4);
  EXPECT_DOUBLE_EQ(o.victoria_park.gate.max_bearing, std::numbers::pi / 3);
  EXPECT_EQ(o.victoria_park.gate.max_diameter, 0.9);
  EXPECT_EQ(o.victoria_park.laser_yaw, 0.0);
  EXPECT_DOUBLE_EQ(run("{}", "--vp-laser-yaw-deg -0.5").victoria_park.laser_yaw,
                   -0.5 * std::numbers::pi / 180);
  // The laser's place on the car (the model's a and b): the README's values unless given.
  const engine::AckermannGeometry nominal = kVictoriaParkGeometry;
  EXPECT_EQ(o.victoria_park.geometry.a, nominal.a);
  EXPECT_EQ(o.victoria_park.geometry.b, nominal.b);
  o = run(R"({"vp-laser-y": 0.25})", "--vp-laser-x 3.6");
  EXPECT_EQ(o.victoria_park.geometry.a, 3.6);
  EXPECT_EQ(o.victoria_park.geometry.b, 0.25);
  EXPECT_EQ(o.victoria_park.geometry.l, nominal.l);
  EXPECT_NE(error_of("{}", "--vp-laser-x 0").find("--vp-laser-x"), std::string::npos);
  EXPECT_NE(error_of("{}", "--vp-max-diameter 0").find("--vp-max-diameter"), std::string::npos);
  EXPECT_NE(error_of("{}", "--vp-min-range -1").find("--vp-min-range"), std::string::npos);
}

}  // namespace
}  // namespace fastslam::tools
