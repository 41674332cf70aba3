// The `fastslam` command line.
#include <cstdio>
#include <exception>
#include <string>

#include <CLI/CLI.hpp>

#include "tools/command_line.h"
#include "tools/memory_demo.h"
#include "tools/run_command.h"

int main(int argc, char** argv) {
  CLI::App app{"fastslam: a parallel, high-throughput FastSLAM 1.0/2.0 engine"};
  app.require_subcommand(1);

  fastslam::tools::RunOptions run;
  fastslam::tools::RunWords words;
  CLI::App* run_cmd = app.add_subcommand(
      "run",
      "run the filter on a simulated world or a native log and write metrics, trajectory and map");
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
  demo_cmd->add_option("--updates-per-step", demo.updates_per_step,
                       "landmarks each particle changes per step (K)")
      ->check(CLI::Range(0U, 1'000'000U));
  demo_cmd->add_option("--seed", demo.seed, "random seed");
  demo_cmd->add_option("--threads", demo.threads, "worker threads (0: all cores)")
      ->check(CLI::Range(0, 1024));
  demo_cmd->add_option("--out", demo.out, "directory to write metrics.json into");

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
    if (demo_cmd->parsed()) return fastslam::tools::run_memory_demo(demo);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fastslam: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
