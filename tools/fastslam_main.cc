// The `fastslam` command line.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "engine/enum_names.h"
#include "engine/filter_config.h"
#include "tools/command_line.h"
#include "tools/lg_slam_experiment.h"
#include "tools/memory_demo.h"
#include "tools/run_command.h"
#include "tools/scaling_study.h"

int main(int argc, char** argv) {
  CLI::App app{"fastslam: a parallel, high-throughput FastSLAM 1.0/2.0 engine"};
  app.require_subcommand(1);

  fastslam::tools::RunOptions run;
  fastslam::tools::RunWords words;
  CLI::App* run_cmd = app.add_subcommand(
      "run",
      "run the filter on a simulated world or a native log and write metrics, trajectory and map; "
      "with no options, the built-in stress run: a grid world of 100000 landmarks (2 m spacing, "
      "1 s scans), FastSLAM 1.0, 100 particles");
  fastslam::tools::add_run_options(*run_cmd, run, words);

  fastslam::tools::RunOptions convert;
  fastslam::tools::RunWords convert_words;
  CLI::App* convert_cmd = app.add_subcommand(
      "convert", "write a simulated world or the Victoria Park data set as a native log file");
  fastslam::tools::add_convert_options(*convert_cmd, convert, convert_words);

  fastslam::tools::MemoryDemoOptions demo;
  CLI::App* demo_cmd = app.add_subcommand(
      "memory-demo",
      "M particles share one N-landmark map, each changes K landmarks a step, then a random "
      "resampling; prints live memory against one map and the linear baseline");
  demo_cmd->add_option("--landmarks", demo.landmarks, "landmarks in the shared map (N)")
      ->check(CLI::Range(1ULL, 100'000'000ULL));
  demo_cmd->add_option("--particles", demo.particles, "particles (M)")
      ->check(CLI::Range(1U, 10'000'000U));
  demo_cmd->add_option("--steps", demo.steps, "steps")->check(CLI::Range(1U, 1'000'000U));
  demo_cmd
      ->add_option("--updates-per-step", demo.updates_per_step,
                   "landmarks each particle changes per step (K)")
      ->check(CLI::Range(0U, 1'000'000U));
  demo_cmd->add_option("--seed", demo.seed, "random seed");
  demo_cmd->add_option("--threads", demo.threads, "worker threads (0: all cores)")
      ->check(CLI::Range(0, 1024));
  demo_cmd->add_option("--out", demo.out, "directory to write metrics.json into");

  // fastslam bench scaling: the scaling study in N (tools/scaling_study.h).
  CLI::App* bench_cmd = app.add_subcommand("bench", "throughput studies");
  bench_cmd->require_subcommand(1);
  fastslam::tools::ScalingOptions scaling;
  std::string scaling_algorithm = "fastslam1", scaling_association = "ml", scaling_json,
              scaling_engine = "tree";
  CLI::App* scaling_cmd = bench_cmd->add_subcommand(
      "scaling",
      "time per sensor update and live memory against map size N at constant density (maps "
      "pre-grown to N, then --updates scans timed), for every N x M x threads of the lists; "
      "prints a table, writes JSON and CSV");
  scaling_cmd->add_option("--landmarks", scaling.landmarks, "map sizes N, comma separated")
      ->delimiter(',')
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{100'000'000}))
      ->capture_default_str();
  scaling_cmd->add_option("--particles", scaling.particles, "particle counts M, comma separated")
      ->delimiter(',')
      ->check(CLI::Range(1U, 10'000'000U))
      ->capture_default_str();
  scaling_cmd->add_option("--updates", scaling.updates, "sensor updates (scans) timed per N")
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1'000'000}))
      ->capture_default_str();
  scaling_cmd
      ->add_option("--engine", scaling_engine,
                   "tree (the filter) or linear (the baseline: flat maps copied at resampling, "
                   "FastSLAM 1.0 with ML only, one thread)")
      ->check(CLI::IsMember({"tree", "linear"}))
      ->capture_default_str();
  scaling_cmd
      ->add_option("--linear-max-landmarks", scaling.linear_max_landmarks,
                   "largest N the linear engine accepts (it is O(M N) per update)")
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{100'000'000}))
      ->capture_default_str();
  std::vector<std::string> fastslam_versions =
      fastslam::engine::enum_names<fastslam::engine::Algorithm>();
  std::erase(fastslam_versions,
             std::string(fastslam::engine::enum_name(fastslam::engine::Algorithm::kEkf)));
  scaling_cmd->add_option("--algorithm", scaling_algorithm, "fastslam1 or fastslam2")
      ->check(CLI::IsMember(fastslam_versions))
      ->capture_default_str();
  scaling_cmd->add_option("--association", scaling_association, "known or ml or das")
      ->check(CLI::IsMember(fastslam::engine::enum_names<fastslam::engine::Association>()))
      ->capture_default_str();
  scaling_cmd
      ->add_option("--threads", scaling.threads,
                   "worker thread counts, comma separated (0: all cores)")
      ->delimiter(',')
      ->check(CLI::Range(0U, 4096U))
      ->capture_default_str();
  scaling_cmd
      ->add_option("--grain", scaling.filter.grain,
                   "particles per parallel task; up to this many run on the calling thread")
      ->check(CLI::Range(std::size_t{1}, std::size_t{1'000'000}))
      ->capture_default_str();
  scaling_cmd
      ->add_option("--split-seconds", scaling.filter.split_seconds,
                   "a pass whose previous one took longer is split across the threads whatever "
                   "--grain (0: always)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  scaling_cmd
      ->add_option("--repeats", scaling.repeats,
                   "runs per point; the fastest is reported, all are kept in the JSON")
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{1000}))
      ->capture_default_str();
  scaling_cmd->add_option("--seed", scaling.filter.seed, "random seed")->capture_default_str();
  scaling_cmd->add_option("--json", scaling_json, "write the points as JSON to this file");
  std::string scaling_csv;
  scaling_cmd->add_option("--csv", scaling_csv, "write the points as CSV to this file");

  // fastslam experiment lg-slam: the convergence experiment of section 7
  // (tools/lg_slam_experiment.h).
  CLI::App* experiment_cmd = app.add_subcommand("experiment", "experiments from the paper");
  experiment_cmd->require_subcommand(1);
  fastslam::tools::LgSlamExperimentOptions lg;
  CLI::App* lg_cmd = experiment_cmd->add_subcommand(
      "lg-slam",
      "FastSLAM 2.0 with M = 1 on linear-Gaussian SLAM (section 7): landmark and pose errors per "
      "step, anchored (landmark 0 known) and relative (offset removed); writes DIR/lg_slam.csv");
  lg_cmd->add_option("--out", lg.out, "directory to write lg_slam.csv into")->required();
  lg_cmd->add_option("--seeds", lg.seeds, "number of seeds")
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{100'000}))
      ->capture_default_str();
  lg_cmd->add_option("--first-seed", lg.first_seed, "the first seed")->capture_default_str();
  lg_cmd->add_option("--steps", lg.steps, "steps per run (default 100000; 2000 with --tiny)")
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{100'000'000}));
  lg_cmd->add_option("--landmarks", lg.world.landmarks, "landmarks on the circle")
      ->check(CLI::Range(std::size_t{1}, std::size_t{100'000}))
      ->capture_default_str();
  lg_cmd->add_option("--particles", lg.particles, "particles (M; the theorem's case is 1)")
      ->check(CLI::Range(std::size_t{1}, std::size_t{1'000'000}))
      ->capture_default_str();
  lg_cmd->add_option("--sensor-range", lg.world.sensor_range, "sensor range, m")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  lg_cmd->add_flag("--tiny", lg.tiny, "a small run (at most 3 seeds, 2000 steps) for tests");

  CLI11_PARSE(app, argc, argv);
  try {
    if (run_cmd->parsed()) {
      if (!words.config.empty()) fastslam::tools::apply_json_config(*run_cmd, words.config);
      fastslam::tools::finish_run_options(*run_cmd, words, run);
      return fastslam::tools::run_simulation(run);
    }
    if (convert_cmd->parsed()) {
      if (!convert_words.config.empty()) {
        fastslam::tools::apply_json_config(*convert_cmd, convert_words.config);
      }
      fastslam::tools::finish_run_options(*convert_cmd, convert_words, convert);
      return fastslam::tools::convert_to_log(convert);
    }
    if (lg_cmd->parsed()) return fastslam::tools::run_lg_slam_command(lg);
    if (demo_cmd->parsed()) return fastslam::tools::run_memory_demo(demo);
    if (scaling_cmd->parsed()) {
      using fastslam::engine::Algorithm;
      using fastslam::engine::Association;
      scaling.engine = scaling_engine == "linear" ? fastslam::tools::ScalingEngine::kLinear
                                                  : fastslam::tools::ScalingEngine::kTree;
      scaling.filter.algorithm = fastslam::engine::parse_enum<Algorithm>(scaling_algorithm);
      scaling.filter.association = fastslam::engine::parse_enum<Association>(scaling_association);
      return fastslam::tools::run_scaling_command(scaling, scaling_json, scaling_csv);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fastslam: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
