// The `fastslam` command line: `run` and `convert` (tools/cli/command_line.h), `sweep`
// (tools/cli/sweep_command.h), `bench scaling`
// (tools/studies/scaling_study.h) and `experiment lg-slam` (tools/studies/lg_slam_experiment.h).
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "engine/enum_names.h"
#include "engine/filter_config.h"
#include "tools/cli/build_info.h"
#include "tools/cli/command_line.h"
#include "tools/cli/mpi_ranks.h"
#include "tools/cli/run_command.h"
#include "tools/cli/run_sweep.h"
#include "tools/cli/sweep_command.h"
#include "tools/studies/lg_slam_experiment.h"
#include "tools/studies/scaling_study.h"

namespace fastslam::tools {
namespace {

// `fastslam bench scaling`: the options, the words turned into enums after parsing.
struct ScalingCommand {
  ScalingOptions options;
  std::string algorithm = "fastslam1", association = "ml", engine = "tree", json, csv;
};

CLI::App* add_scaling_command(CLI::App& bench, ScalingCommand& c) {
  CLI::App* cmd = bench.add_subcommand(
      "scaling",
      "time per sensor update and live memory against map size N at constant density (maps "
      "pre-grown to N, then --updates scans timed), for every N x M x threads of the lists; "
      "prints a table, writes JSON and CSV");
  cmd->add_option("--landmarks", c.options.landmarks, "map sizes N, comma separated")
      ->delimiter(',')
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{100'000'000}))
      ->capture_default_str();
  cmd->add_option("--particles", c.options.particles, "particle counts M, comma separated")
      ->delimiter(',')
      ->check(CLI::Range(1U, 10'000'000U))
      ->capture_default_str();
  cmd->add_option("--updates", c.options.updates, "sensor updates (scans) timed per N")
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1'000'000}))
      ->capture_default_str();
  cmd->add_option("--engine", c.engine,
                  "tree (the filter) or linear (the baseline: flat maps copied at resampling, "
                  "FastSLAM 1.0 with ML only, one thread)")
      ->check(CLI::IsMember({"tree", "linear"}))
      ->capture_default_str();
  cmd->add_option("--linear-max-landmarks", c.options.linear_max_landmarks,
                  "largest N the linear engine accepts (it is O(M N) per update)")
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{100'000'000}))
      ->capture_default_str();
  std::vector<std::string> versions = engine::enum_names<engine::Algorithm>();
  std::erase(versions, std::string(engine::enum_name(engine::Algorithm::kEkf)));
  cmd->add_option("--algorithm", c.algorithm, "fastslam1 or fastslam2")
      ->check(CLI::IsMember(versions))
      ->capture_default_str();
  cmd->add_option("--association", c.association, "known or ml or das")
      ->check(CLI::IsMember(engine::enum_names<engine::Association>()))
      ->capture_default_str();
  cmd->add_option("--threads", c.options.threads,
                  "worker thread counts, comma separated (0: all cores)")
      ->delimiter(',')
      ->check(CLI::Range(0U, 4096U))
      ->capture_default_str();
  cmd->add_option("--grain", c.options.filter.grain,
                  "particles per parallel task; up to this many run on the calling thread")
      ->check(CLI::Range(std::size_t{1}, std::size_t{1'000'000}))
      ->capture_default_str();
  cmd->add_option("--split-seconds", c.options.filter.split_seconds,
                  "a pass whose previous one took longer is split across the threads whatever "
                  "--grain (0: always)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cmd->add_option("--repeats", c.options.repeats,
                  "runs per point; the fastest is reported, all are kept in the JSON")
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1000}))
      ->capture_default_str();
  cmd->add_option("--seed", c.options.filter.seed, "random seed")->capture_default_str();
  cmd->add_option("--json", c.json, "write the points as JSON to this file");
  cmd->add_option("--csv", c.csv, "write the points as CSV to this file");

  return cmd;
}

int finish_and_run_scaling(ScalingCommand& c) {
  using engine::Algorithm;
  using engine::Association;
  c.options.engine = c.engine == "linear" ? ScalingEngine::kLinear : ScalingEngine::kTree;
  c.options.filter.algorithm = engine::parse_enum<Algorithm>(c.algorithm);
  c.options.filter.association = engine::parse_enum<Association>(c.association);
  // Under mpirun every point's particles are spread over the ranks (docs/distributed.md).
  const Launch launch = launch_environment();
  if (launch.launched && launch.size > 1 && !have_mpi()) {
    throw std::runtime_error("this fastslam was built without MPI but was started as one of " +
                             std::to_string(launch.size) + " processes (mpirun)");
  }
  const Ranks ranks(launch.launched && launch.size > 1);
  if (ranks.size() > 1) c.options.group = ranks.collective();
  const int code = run_scaling_command(c.options, c.json, c.csv);
  c.options.group.reset();  // before MPI is finalised
  return code;
}

// `fastslam experiment lg-slam`: the convergence experiment of section 7.
CLI::App* add_lg_slam_command(CLI::App& experiment, LgSlamExperimentOptions& lg) {
  CLI::App* cmd = experiment.add_subcommand(
      "lg-slam",
      "FastSLAM 2.0 with M = 1 on linear-Gaussian SLAM (section 7): landmark and pose errors per "
      "step, anchored (landmark 0 known) and relative (offset removed); writes DIR/lg_slam.csv");
  cmd->add_option("--out", lg.out, "directory to write lg_slam.csv into")->required();
  cmd->add_option("--seeds", lg.seeds, "number of seeds")
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{100'000}))
      ->capture_default_str();
  cmd->add_option("--first-seed", lg.first_seed, "the first seed")->capture_default_str();
  cmd->add_option("--steps", lg.steps, "steps per run (default 100000; 2000 with --tiny)")
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{100'000'000}));
  cmd->add_option("--landmarks", lg.world.landmarks, "landmarks on the circle")
      ->check(CLI::Range(std::size_t{1}, std::size_t{100'000}))
      ->capture_default_str();
  cmd->add_option("--particles", lg.particles, "particles (M; the theorem's case is 1)")
      ->check(CLI::Range(std::size_t{1}, std::size_t{1'000'000}))
      ->capture_default_str();
  cmd->add_option("--sensor-range", lg.world.sensor_range, "sensor range, m")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd->add_flag("--tiny", lg.tiny, "a small run (at most 3 seeds, 2000 steps) for tests");

  return cmd;
}

// `fastslam sweep`: its own options; every other argument is a `fastslam run` option, the
// base of every run (parsed per configuration by tools/cli/sweep_grid.h).
CLI::App* add_sweep_command(CLI::App& app, SweepOptions& s) {
  CLI::App* cmd = app.add_subcommand(
      "sweep",
      "run a grid of seeds x options x sources (a JSON file, --grid flags), each as `fastslam "
      "run` into OUT/NAME/seed-S, over --jobs local threads or, under mpirun, over MPI ranks; "
      "writes OUT/sweep.json (a summary per configuration) and OUT/sweep.csv (a row per run); "
      "a rerun skips the runs already complete. Any `fastslam run` option (e.g. --seeds 1-10 "
      "--max-steps 500) is the base of every run");
  cmd->add_option("--config", s.request.config,
                  "the sweep file: {\"base\": {run options}, \"seeds\": \"1-10\", \"grid\": "
                  "{\"particles\": [100, 1000]}, \"sources\": [{\"name\": ..., run options}]}")
      ->check(CLI::ExistingFile);
  cmd->add_option("--out", s.request.out, "the sweep's directory")->required();
  cmd->add_option("--grid", s.request.grid,
                  "an axis KEY=V1,V2,... (repeatable), replacing the file's grid KEY");
  cmd->add_option("--jobs", s.jobs,
                  "runs at once in each process (default 0: the cores of this node divided by "
                  "its ranks and each run's --threads); each run then gets cores / jobs threads "
                  "unless --threads says")
      ->check(CLI::Range(0U, 4096U))
      ->capture_default_str();
  cmd->add_flag("--dry-run", s.dry_run,
                "print the runs in the order they would start, and which are already done");
  cmd->allow_extras();
  return cmd;
}

}  // namespace
}  // namespace fastslam::tools

int main(int argc, char** argv) {
  namespace tools = fastslam::tools;
  CLI::App app{"fastslam: a parallel, high-throughput FastSLAM 1.0/2.0 engine"};
  app.require_subcommand(1);
  app.set_version_flag(
      "--version", [] { return fastslam::tools::version_text(); },
      "print the version, git commit, build type, compiler and SIMD level");

  tools::RunOptions run;
  tools::RunWords words;
  CLI::App* run_cmd = app.add_subcommand(
      "run",
      "run the filter on a source (a simulated world, a native log, a data set) and write "
      "metrics, trajectory and map; with no options, the built-in stress run: a grid world of "
      "100000 landmarks (2 m spacing, 1 s scans), FastSLAM 1.0, 100 particles");
  tools::add_run_options(*run_cmd, run, words);

  tools::RunOptions convert;
  tools::RunWords convert_words;
  CLI::App* convert_cmd = app.add_subcommand(
      "convert", "write any source (a simulated world, a data set) as a native log file");
  tools::add_convert_options(*convert_cmd, convert, convert_words);

  tools::SweepOptions sweep;
  CLI::App* sweep_cmd = tools::add_sweep_command(app, sweep);

  CLI::App* bench_cmd = app.add_subcommand("bench", "throughput studies");
  bench_cmd->require_subcommand(1);
  tools::ScalingCommand scaling;
  CLI::App* scaling_cmd = tools::add_scaling_command(*bench_cmd, scaling);

  CLI::App* experiment_cmd = app.add_subcommand("experiment", "experiments from the paper");
  experiment_cmd->require_subcommand(1);
  tools::LgSlamExperimentOptions lg;
  CLI::App* lg_cmd = tools::add_lg_slam_command(*experiment_cmd, lg);

  CLI11_PARSE(app, argc, argv);
  try {
    if (run_cmd->parsed()) {
      if (!words.config.empty()) tools::apply_json_config(*run_cmd, words.config);
      tools::finish_run_options(*run_cmd, words, run);
      return run.seeds.empty() ? tools::run_simulation(run) : tools::run_sweep(run);
    }
    if (sweep_cmd->parsed()) {
      sweep.request.run_args = sweep_cmd->remaining();
      return tools::run_sweep_command(sweep);
    }
    if (convert_cmd->parsed()) {
      if (!convert_words.config.empty())
        tools::apply_json_config(*convert_cmd, convert_words.config);
      tools::finish_run_options(*convert_cmd, convert_words, convert);
      return tools::convert_to_log(convert);
    }
    if (lg_cmd->parsed()) return tools::run_lg_slam_command(lg);
    if (scaling_cmd->parsed()) return tools::finish_and_run_scaling(scaling);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fastslam: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
