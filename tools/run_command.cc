#include "tools/run_command.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <stdexcept>
#include <sys/resource.h>
#include <unistd.h>
#include <vector>

#include <nlohmann/json.hpp>
#include <oneapi/tbb/info.h>

#include "engine/ekf_slam.h"
#include "engine/filter.h"

namespace fastslam::tools {
namespace {

using Clock = std::chrono::steady_clock;

std::int64_t peak_rss_bytes() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<std::int64_t>(usage.ru_maxrss) * 1024;
}

World make_world(const RunOptions& o) {
  if (!o.landmarks_csv.empty() || !o.waypoints_csv.empty()) {
    if (o.landmarks_csv.empty() || o.waypoints_csv.empty()) {
      throw std::invalid_argument("--landmarks-csv and --waypoints-csv go together");
    }
    return read_world_csv(o.landmarks_csv, o.waypoints_csv);
  }
  if (o.world == "grid") {
    return make_grid_world(o.landmarks, o.spacing, 1.5 * o.sim.max_range, o.filter.seed);
  }
  if (o.world == "loop") {
    return make_loop_world(o.loop_length, o.spacing, o.sim.max_range, 10.0, o.filter.seed);
  }
  throw std::invalid_argument("unknown --world '" + o.world + "' (grid or loop)");
}

// A one-line progress bar on stderr, redrawn at most ten times a second.
class Progress {
 public:
  explicit Progress(bool enabled) : enabled_(enabled && isatty(STDERR_FILENO) != 0) {}
  void update(double fraction, std::uint64_t scans, std::uint64_t observations) {
    if (!enabled_) return;
    const auto now = Clock::now();
    if (now - last_ < std::chrono::milliseconds(100) && fraction < 1.0) return;
    last_ = now;
    const int width = 40;
    const int filled = static_cast<int>(fraction * width);
    std::fprintf(stderr, "\r[%.*s%*s] %5.1f%%  %llu scans  %llu observations", filled,
                 "########################################", width - filled, "", 100 * fraction,
                 static_cast<unsigned long long>(scans),
                 static_cast<unsigned long long>(observations));
    std::fflush(stderr);
  }
  void finish() {
    if (enabled_) std::fprintf(stderr, "\n");
  }

 private:
  bool enabled_;
  Clock::time_point last_{};
};

// What one run of an estimator through the simulator produced.
struct Drive {
  std::vector<TruePose> truth;
  std::vector<double> times;
  engine::Estimate estimate;
  std::vector<engine::TrajectoryPoint> trajectory;
  engine::FilterStatistics stats;
  double sim_seconds = 0.0;
  double filter_seconds = 0.0;
};

// The simulation loop, the same for the FastSLAM `Filter` and `EkfSlam` (same method names).
template <class Estimator>
Drive drive(Estimator&& filter, Simulator& sim, Progress& progress, double expected_steps) {
  Drive out;
  std::vector<engine::Observation> scan;
  SimStep step;
  double t = 0.0;
  std::uint64_t scans = 0;
  for (;;) {
    const auto t0 = Clock::now();
    if (!sim.next(step)) break;
    const auto t1 = Clock::now();
    t += step.dt;
    out.truth.push_back(step.truth);
    out.times.push_back(t);
    filter.predict({step.speed, step.steer}, step.dt);
    if (step.has_scan) {
      scan.clear();
      for (const SimObservation& z : step.scan) {
        scan.push_back({z.range, z.bearing, static_cast<std::int64_t>(z.landmark)});
      }
      filter.observe(scan);
      ++scans;
      if (scans % 64 == 0) {
        progress.update(std::min(1.0, double(out.truth.size()) / expected_steps), scans,
                        filter.statistics().observations);
      }
    }
    out.sim_seconds += std::chrono::duration<double>(t1 - t0).count();
    out.filter_seconds += std::chrono::duration<double>(Clock::now() - t1).count();
  }
  const auto t_end = Clock::now();
  out.estimate = filter.estimate();
  out.trajectory = filter.take_trajectory();
  out.filter_seconds += std::chrono::duration<double>(Clock::now() - t_end).count();
  out.stats = filter.statistics();
  progress.update(1.0, scans, out.stats.observations);
  progress.finish();
  return out;
}

}  // namespace

int run_simulation(const RunOptions& options) {
  if (options.source != "sim") {
    throw std::invalid_argument("--source '" + options.source + "' is not supported yet (sim)");
  }
  const World world = make_world(options);
  engine::FilterConfig config = options.filter;
  config.record_trajectory = true;
  config.sensor.sigma_range = options.sim.sigma_range;
  config.sensor.sigma_bearing = options.sim.sigma_bearing;
  config.sensor.max_range = options.sim.max_range;
  config.sensor.field_of_view = options.sim.field_of_view;
  config.motion.kind = engine::MotionKind::kBaileyCar;
  config.motion.wheelbase = options.sim.wheelbase;
  config.motion.sigma_control[0] = options.sim.sigma_v;
  config.motion.sigma_control[1] = options.sim.sigma_steer;
  config.initial_pose[0] = world.start_x;
  config.initial_pose[1] = world.start_y;
  config.initial_pose[2] = world.start_theta;

  // The route length bounds the number of steps, for the progress bar.
  double route = 0.0;
  for (std::size_t i = 0; i < world.waypoints.size(); ++i) {
    const Point& a = world.waypoints[i];
    const Point& b = world.waypoints[(i + 1) % world.waypoints.size()];
    route += std::hypot(b.x - a.x, b.y - a.y);
  }
  const double expected_steps =
      std::max(1.0, route * options.sim.loops / (options.sim.speed * options.sim.dt));

  Simulator sim(world, options.sim, config.seed);
  Progress progress(options.progress);
  const Drive run = config.algorithm == engine::Algorithm::kEkf
                        ? drive(engine::EkfSlam(config), sim, progress, expected_steps)
                        : drive(engine::Filter(config), sim, progress, expected_steps);
  const std::vector<TruePose>& truth = run.truth;
  const std::vector<double>& times = run.times;
  const engine::Estimate& estimate = run.estimate;
  const std::vector<engine::TrajectoryPoint>& trajectory = run.trajectory;
  const double sim_seconds = run.sim_seconds;
  const double filter_seconds = run.filter_seconds;

  double pose_se = 0.0;
  for (const engine::TrajectoryPoint& p : trajectory) {
    const TruePose& s = truth[p.control];
    pose_se += (p.x - s.x) * (p.x - s.x) + (p.y - s.y) * (p.y - s.y);
  }
  const double pose_rmse = trajectory.empty() ? 0.0 : std::sqrt(pose_se / trajectory.size());
  // Each estimate against its true landmark: by id with known association, else the nearest.
  double landmark_se = 0.0;
  const bool known_ids = config.association == engine::Association::kKnown;
  const std::unique_ptr<TruthIndex> true_index =
      known_ids || world.landmarks.empty() ? nullptr
                                           : std::make_unique<TruthIndex>(world.landmarks);
  for (const engine::MapLandmark& l : estimate.map) {
    const Point& p = world.landmarks.at(known_ids ? l.id : true_index->nearest(l.x, l.y).first);
    landmark_se += (l.x - p.x) * (l.x - p.x) + (l.y - p.y) * (l.y - p.y);
  }
  const double landmark_rmse =
      estimate.map.empty() ? 0.0 : std::sqrt(landmark_se / estimate.map.size());
  const engine::FilterStatistics& stats = run.stats;
  const std::uint32_t particles =
      config.algorithm == engine::Algorithm::kEkf ? 1 : config.particles;
  const TruePose& last = truth.back();

  nlohmann::json metrics = {
      {"source", options.source},
      {"world", options.landmarks_csv.empty() ? options.world : options.landmarks_csv},
      {"algorithm", engine::to_string(config.algorithm)},
      {"particles", particles},
      {"association", engine::to_string(config.association)},
      {"seed", config.seed},
      {"threads", config.threads > 0 ? config.threads : unsigned(tbb::info::default_concurrency())},
      {"steps", stats.controls},
      {"scans", stats.scans},
      {"observations", stats.observations},
      {"true_landmarks", world.landmarks.size()},
      {"landmarks", estimate.map.size()},
      {"wall_seconds", filter_seconds},
      {"simulator_seconds", sim_seconds},
      {"seconds_per_phase",
       {{"predict", stats.predict_seconds},
        {"update", stats.update_seconds},
        {"resample", stats.resample_seconds}}},
      {"resamples", stats.resamples},
      {"live_tree_nodes", stats.live_nodes},
      {"live_tree_bytes", stats.live_bytes},
      {"peak_rss_bytes", peak_rss_bytes()},
      {"pose_rmse_m", pose_rmse},
      {"landmark_rmse_m", landmark_rmse},
      {"final_position_error_m",
       std::hypot(estimate.mean_pose[0] - last.x, estimate.mean_pose[1] - last.y)},
  };
  std::printf("%s, M = %u, %s association, seed %llu: %llu steps, %llu scans, %zu landmarks\n",
              std::string(engine::to_string(config.algorithm)).c_str(), particles,
              std::string(engine::to_string(config.association)).c_str(),
              static_cast<unsigned long long>(config.seed),
              static_cast<unsigned long long>(stats.controls),
              static_cast<unsigned long long>(stats.scans), estimate.map.size());
  std::printf("  pose RMSE %.3f m, landmark RMSE %.3f m, filter %.3f s (simulator %.3f s)\n",
              pose_rmse, landmark_rmse, filter_seconds, sim_seconds);
  if (options.out.empty()) return 0;

  std::filesystem::create_directories(options.out);
  auto open = [&](const std::string& name) {
    std::ofstream file(options.out + "/" + name);
    if (!file) throw std::runtime_error("cannot write " + options.out + "/" + name);
    return file;
  };
  open("metrics.json") << metrics.dump(2) << '\n';
  {
    std::ofstream file = open("trajectory.csv");
    file << "t,x,y,theta\n";
    char line[160];
    for (const engine::TrajectoryPoint& p : trajectory) {
      std::snprintf(line, sizeof(line), "%.3f,%.6f,%.6f,%.6f\n", times[p.control], p.x, p.y,
                    p.theta);
      file << line;
    }
  }
  {
    std::ofstream file = open("landmarks.csv");
    file << "id,x,y,sxx,sxy,syy\n";
    char line[200];
    for (const engine::MapLandmark& l : estimate.map) {
      std::snprintf(line, sizeof(line), "%llu,%.6f,%.6f,%.9g,%.9g,%.9g\n",
                    static_cast<unsigned long long>(l.id), l.x, l.y, l.sxx, l.sxy, l.syy);
      file << line;
    }
  }
  {
    std::ofstream file = open("truth.csv");
    file << "t,x,y,theta\n";
    char line[160];
    for (std::size_t k = 0; k < truth.size(); ++k) {
      std::snprintf(line, sizeof(line), "%.3f,%.6f,%.6f,%.6f\n", times[k], truth[k].x, truth[k].y,
                    truth[k].theta);
      file << line;
    }
  }
  {
    std::ofstream file = open("true_landmarks.csv");
    file << "id,x,y\n";
    char line[120];
    for (std::size_t i = 0; i < world.landmarks.size(); ++i) {
      std::snprintf(line, sizeof(line), "%zu,%.6f,%.6f\n", i, world.landmarks[i].x,
                    world.landmarks[i].y);
      file << line;
    }
  }
  std::printf("  wrote %s/{metrics.json,trajectory.csv,landmarks.csv,truth.csv,true_landmarks.csv}\n",
              options.out.c_str());
  return 0;
}

}  // namespace fastslam::tools
