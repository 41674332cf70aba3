#include "tools/scaling_study.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "engine/filter.h"
#include "tools/linear_baseline.h"
#include "tools/simulator.h"
#include "tools/world.h"

namespace fastslam::tools {
namespace {

struct Step {
  engine::Control control;
  double dt = 0.0;
  bool has_scan = false;
  std::vector<engine::Observation> scan;
  TruePose truth;
};

// The first `scans` scans of the route (with the controls before them); observations carry
// the true ids (used only under known association).
std::vector<Step> simulate(const World& world, std::uint64_t scans, std::uint64_t seed) {
  Simulator sim(world, SimConfig{}, seed);
  SimStep s;
  std::vector<Step> out;
  std::uint64_t seen = 0;
  while (seen < scans && sim.next(s)) {
    Step step{{s.speed, s.steer}, s.dt, s.has_scan, {}, s.truth};
    for (const SimObservation& z : s.scan) {
      step.scan.push_back({z.range, z.bearing, static_cast<std::int64_t>(z.landmark)});
    }
    seen += s.has_scan ? 1 : 0;
    out.push_back(std::move(step));
  }
  return out;
}

void check_limits(const ScalingOptions& options, std::uint64_t landmarks) {
  if (landmarks == 0) throw std::invalid_argument("scaling: landmarks must be at least 1");
  if (options.updates == 0) throw std::invalid_argument("scaling: updates must be at least 1");
  if (options.engine == ScalingEngine::kLinear && landmarks > options.linear_max_landmarks) {
    throw std::invalid_argument(
        "scaling: the linear baseline costs O(M N) time and memory per update; N = " +
        std::to_string(landmarks) + " is above its cap of " +
        std::to_string(options.linear_max_landmarks) + " landmarks (--linear-max-landmarks)");
  }
}

// The linear baseline over the same steps and prior (tools/linear_baseline.h).
ScalingPoint run_linear_point(const engine::FilterConfig& config, const std::vector<Step>& steps,
                              const std::vector<engine::MapLandmark>& prior) {
  LinearFastSlam filter(config);
  filter.set_map(prior);
  ScalingPoint p;
  p.lower_bound_bytes = static_cast<std::int64_t>(prior.size() * sizeof(memory::Landmark));
  const auto t0 = std::chrono::steady_clock::now();
  for (const Step& step : steps) {
    filter.predict(step.control, step.dt);
    if (step.has_scan) filter.observe(step.scan);
  }
  const engine::Pose mean = filter.mean_pose();
  p.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const LinearStatistics& st = filter.statistics();
  p.updates = st.scans;
  p.observations = st.observations;
  p.live_bytes = filter.live_bytes();
  p.predict_seconds = st.predict_seconds;
  p.associate_seconds = st.associate_seconds;
  p.update_seconds = st.update_seconds;
  p.resample_seconds = st.resample_seconds;
  if (!steps.empty()) {
    p.pose_error = std::hypot(mean[0] - steps.back().truth.x, mean[1] - steps.back().truth.y);
  }
  return p;
}

}  // namespace

std::string_view to_string(ScalingEngine engine) {
  return engine == ScalingEngine::kLinear ? "linear" : "tree";
}

ScalingPoint run_scaling_point(const ScalingOptions& options, std::uint64_t landmarks) {
  check_limits(options, landmarks);
  engine::validate(options.filter);
  const World world = make_grid_world(landmarks, options.spacing, 45.0, options.filter.seed);
  const std::vector<Step> steps = simulate(world, options.updates, options.filter.seed);
  std::vector<engine::MapLandmark> prior;
  prior.reserve(world.landmarks.size());
  for (std::size_t i = 0; i < world.landmarks.size(); ++i) {
    prior.push_back({0, i, world.landmarks[i].x, world.landmarks[i].y, 0.1, 0.0, 0.1, 50.0, 0});
  }
  engine::FilterConfig config = options.filter;
  config.initial_pose[0] = world.start_x;
  config.initial_pose[1] = world.start_y;
  config.initial_pose[2] = world.start_theta;
  if (options.engine == ScalingEngine::kLinear) {
    ScalingPoint p = run_linear_point(config, steps, prior);
    p.landmarks = landmarks;
    p.seconds_per_update = p.updates == 0 ? 0.0 : p.seconds / static_cast<double>(p.updates);
    return p;
  }
  engine::Filter filter(config);
  filter.set_map(prior);
  ScalingPoint p;
  p.landmarks = landmarks;
  p.lower_bound_bytes = filter.statistics().live_bytes;
  const auto t0 = std::chrono::steady_clock::now();
  for (const Step& step : steps) {
    filter.predict(step.control, step.dt);
    if (step.has_scan) filter.observe(step.scan);
  }
  const engine::Estimate estimate = filter.estimate();
  p.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!steps.empty()) {
    p.pose_error = std::hypot(estimate.mean_pose[0] - steps.back().truth.x,
                              estimate.mean_pose[1] - steps.back().truth.y);
  }
  const engine::FilterStatistics st = filter.statistics();
  p.updates = st.scans;
  p.observations = st.observations;
  p.seconds_per_update = p.updates == 0 ? 0.0 : p.seconds / static_cast<double>(p.updates);
  p.live_bytes = st.live_bytes;
  p.predict_seconds = st.predict_seconds;
  p.associate_seconds = st.associate_seconds;
  p.update_seconds = st.update_seconds;
  p.resample_seconds = st.resample_seconds;
  return p;
}

int run_scaling_command(const ScalingOptions& options, const std::string& json_path) {
  const engine::FilterConfig& f = options.filter;
  for (const std::uint64_t n : options.landmarks) check_limits(options, n);
  if (options.engine == ScalingEngine::kLinear) (void)LinearFastSlam(f);  // refuses early
  std::printf(
      "scaling: %s engine, %s, M = %u, %s association, %llu updates per point, "
      "threads %u\n",
      std::string(to_string(options.engine)).c_str(),
      std::string(engine::to_string(f.algorithm)).c_str(), f.particles,
      std::string(engine::to_string(f.association)).c_str(),
      static_cast<unsigned long long>(options.updates),
      options.engine == ScalingEngine::kLinear ? 1u : f.threads);
  std::printf("%12s %10s %14s %12s %12s %10s %10s\n", "landmarks", "obs/upd", "us/update",
              "live MiB", "1 map MiB", "live/map", "error m");
  nlohmann::json points = nlohmann::json::array();
  for (const std::uint64_t n : options.landmarks) {
    const ScalingPoint p = run_scaling_point(options, n);
    const double mib = 1.0 / (1 << 20);
    std::printf(
        "%12llu %10.1f %14.1f %12.2f %12.2f %10.2f %10.2f\n", static_cast<unsigned long long>(n),
        static_cast<double>(p.observations) / static_cast<double>(p.updates),
        1e6 * p.seconds_per_update, static_cast<double>(p.live_bytes) * mib,
        static_cast<double>(p.lower_bound_bytes) * mib,
        static_cast<double>(p.live_bytes) / static_cast<double>(p.lower_bound_bytes), p.pose_error);
    std::fflush(stdout);
    points.push_back({{"landmarks", n},
                      {"updates", p.updates},
                      {"observations", p.observations},
                      {"seconds", p.seconds},
                      {"seconds_per_update", p.seconds_per_update},
                      {"live_bytes", p.live_bytes},
                      {"lower_bound_bytes", p.lower_bound_bytes},
                      {"pose_error_m", p.pose_error},
                      {"seconds_per_phase",
                       {{"predict", p.predict_seconds},
                        {"associate", p.associate_seconds},
                        {"update", p.update_seconds},
                        {"resample", p.resample_seconds}}}});
  }
  if (!json_path.empty()) {
    const nlohmann::json out = {
        {"config",
         {{"engine", to_string(options.engine)},
          {"algorithm", engine::to_string(f.algorithm)},
          {"particles", f.particles},
          {"association", engine::to_string(f.association)},
          {"threads", options.engine == ScalingEngine::kLinear ? 1u : f.threads},  // used
          {"resample", options.engine == ScalingEngine::kLinear ? std::string("every scan")
                       : f.resample.when == parallel::ResamplePolicy::When::kEveryStep
                           ? std::string("every scan")
                           : "ess < " + std::to_string(f.resample.ess_fraction) + " M"},
          {"seed", f.seed},
          {"updates", options.updates},
          {"spacing_m", options.spacing}}},
        {"points", points}};
    std::ofstream file(json_path);
    if (!(file << out.dump(2) << '\n')) throw std::runtime_error("cannot write " + json_path);
  }
  return 0;
}

}  // namespace fastslam::tools
