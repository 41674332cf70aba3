// The `fastslam` command line.
#include <cstdio>
#include <exception>
#include <string>

#include <CLI/CLI.hpp>

#include "tools/memory_demo.h"
#include "tools/run_command.h"

namespace {

using fastslam::engine::Algorithm;
using fastslam::engine::Association;
using fastslam::parallel::ResamplePolicy;
using fastslam::parallel::ResampleScheme;

// Options parsed as words, turned into the config's enums after parsing.
struct Words {
  int loops = 0;
  std::string algorithm = "fastslam1";
  std::string association = "known";
  std::string resample = "neff";
  std::string scheme = "systematic";
};

void add_run_options(CLI::App& cmd, fastslam::tools::RunOptions& o, Words& w) {
  fastslam::engine::FilterConfig& f = o.filter;
  cmd.add_option("--source", o.source, "where observations come from")
      ->check(CLI::IsMember({"sim"}))
      ->capture_default_str();
  cmd.add_option("--landmarks-csv", o.landmarks_csv,
                 "world landmarks (id,x_m,y_m), e.g. ../shared/data/bailey_sim/"
                 "example_webmap_landmarks.csv")
      ->check(CLI::ExistingFile);
  cmd.add_option("--waypoints-csv", o.waypoints_csv, "world route (index,x_m,y_m)")
      ->check(CLI::ExistingFile);
  cmd.add_option("--world", o.world, "procedural world when no CSV is given")
      ->check(CLI::IsMember({"grid", "loop"}))
      ->capture_default_str();
  cmd.add_option("--landmarks", o.landmarks, "landmarks of a grid world")
      ->check(CLI::Range(std::uint64_t{1}, std::uint64_t{100'000'000}))
      ->capture_default_str();
  cmd.add_option("--spacing", o.spacing, "metres per landmark in procedural worlds")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd.add_option("--loop-length", o.loop_length, "length of a loop world, metres")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd.add_option("--loops", w.loops, "times the route is driven (default: 2 for CSV worlds, 1 else)")
      ->check(CLI::Range(1, 1000));
  cmd.add_option("--algorithm", w.algorithm, "FastSLAM version, or ekf (the EKF-SLAM baseline)")
      ->check(CLI::IsMember({"fastslam1", "fastslam2", "ekf"}))
      ->capture_default_str();
  cmd.add_option("--particles", f.particles, "particles (M)")
      ->check(CLI::Range(1U, 100'000'000U))
      ->capture_default_str();
  cmd.add_option("--association", w.association,
                 "data association: known (ids from the simulator) or ml (ekf only so far)")
      ->check(CLI::IsMember({"known", "ml"}))
      ->capture_default_str();
  cmd.add_option("--ekf-gate-accept", f.ekf.gate_accept,
                 "ekf with ml: associate when the squared Mahalanobis distance is below this")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd.add_option("--ekf-gate-new", f.ekf.gate_new,
                 "ekf with ml: a new landmark when every squared Mahalanobis distance exceeds it")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cmd.add_flag("--ekf-jcbb", f.ekf.joint_compatibility,
               "ekf with ml: joint compatibility branch and bound instead of greedy nearest");
  cmd.add_option("--seed", f.seed, "random seed (the whole run is a function of it)")
      ->capture_default_str();
  cmd.add_option("--threads", f.threads, "worker threads (0: all cores)")
      ->check(CLI::Range(0U, 4096U))
      ->capture_default_str();
  cmd.add_option("--grain", f.grain, "particles per parallel task")
      ->check(CLI::Range(std::size_t{1}, std::size_t{1} << 30))
      ->capture_default_str();
  cmd.add_option("--resample", w.resample, "when to resample: every (scan) or neff")
      ->check(CLI::IsMember({"every", "neff"}))
      ->capture_default_str();
  cmd.add_option("--neff-fraction", f.resample.ess_fraction,
                 "with --resample neff: resample when N_eff < fraction x M")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  cmd.add_option("--resample-scheme", w.scheme, "how to draw the ancestors")
      ->check(CLI::IsMember({"systematic", "stratified", "multinomial"}))
      ->capture_default_str();
  cmd.add_option("--out", o.out, "directory for metrics.json, trajectory.csv, landmarks.csv");
  cmd.add_flag("!--no-progress", o.progress, "no progress bar");
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"fastslam: a parallel, high-throughput FastSLAM 1.0/2.0 engine"};
  app.require_subcommand(1);

  fastslam::tools::RunOptions run;
  Words words;
  CLI::App* run_cmd = app.add_subcommand(
      "run", "run the filter on a simulated world and write metrics, trajectory and map");
  add_run_options(*run_cmd, run, words);

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
      const bool csv = !run.landmarks_csv.empty();
      run.sim.loops = words.loops > 0 ? words.loops : (csv ? 2 : 1);
      run.filter.algorithm = words.algorithm == "ekf"         ? Algorithm::kEkf
                             : words.algorithm == "fastslam2" ? Algorithm::kFastSlam2
                                                              : Algorithm::kFastSlam1;
      run.filter.association =
          words.association == "ml" ? Association::kMaximumLikelihood : Association::kKnown;
      run.filter.resample.when = words.resample == "every"
                                     ? ResamplePolicy::When::kEveryStep
                                     : ResamplePolicy::When::kEssBelowFraction;
      run.filter.resample.scheme = words.scheme == "stratified"    ? ResampleScheme::kStratified
                                   : words.scheme == "multinomial" ? ResampleScheme::kMultinomial
                                                                   : ResampleScheme::kSystematic;
      return fastslam::tools::run_simulation(run);
    }
    if (demo_cmd->parsed()) return fastslam::tools::run_memory_demo(demo);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "fastslam: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
