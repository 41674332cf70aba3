#include "tools/studies/lg_slam_experiment.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

#include "parallel/random_stream.h"
#include "tools/io/atomic_file.h"

namespace fastslam::tools {
namespace {

// Stream particles of Purpose::kSimulator at (seed, step): the motion and the sensor noise.
constexpr std::uint32_t kMotionStream = 0;
constexpr std::uint32_t kSensorStream = 1;

Eigen::Vector2d waypoint(const LgSlamWorldConfig& world, std::uint64_t index) {
  // Start half-way between landmarks 0 and 1, so that the anchor is in view from the start.
  const double spacing = 2.0 * std::numbers::pi / static_cast<double>(world.landmarks);
  const double angle = 0.5 * spacing + 2.0 * std::numbers::pi *
                                           static_cast<double>(index % world.steps_per_loop) /
                                           static_cast<double>(world.steps_per_loop);
  return world.path_radius * Eigen::Vector2d(std::cos(angle), std::sin(angle));
}

}  // namespace

void validate(const LgSlamWorldConfig& world) {
  auto fail = [](const char* what) {
    throw std::invalid_argument(std::string("LgSlamWorldConfig.") + what);
  };
  if (world.landmarks == 0) fail("landmarks must be >= 1");
  if (!(world.landmark_radius >= 0.0) || !std::isfinite(world.landmark_radius)) {
    fail("landmark_radius must be finite and >= 0");
  }
  if (!(world.path_radius >= 0.0) || !std::isfinite(world.path_radius)) {
    fail("path_radius must be finite and >= 0");
  }
  if (world.steps_per_loop < 3) fail("steps_per_loop must be >= 3");
  if (!(world.sensor_range > 0.0)) fail("sensor_range must be > 0");
  if (!(world.sigma_motion >= 0.0) || !std::isfinite(world.sigma_motion)) {
    fail("sigma_motion must be finite and >= 0");
  }
  if (!(world.sigma_measurement > 0.0) || !std::isfinite(world.sigma_measurement)) {
    fail("sigma_measurement must be finite and > 0");
  }
}

LgSlamSimulator::LgSlamSimulator(const LgSlamWorldConfig& world, std::uint64_t seed)
    : world_(world), seed_(seed) {
  validate(world);
  landmarks_.reserve(world.landmarks);
  for (std::size_t k = 0; k < world.landmarks; ++k) {
    const double angle =
        2.0 * std::numbers::pi * static_cast<double>(k) / static_cast<double>(world.landmarks);
    landmarks_.push_back(world.landmark_radius * Eigen::Vector2d(std::cos(angle), std::sin(angle)));
  }
  pose_ = waypoint(world, 0);  // the robot starts exactly known, on its first waypoint
}

void LgSlamSimulator::step(Eigen::Vector2d& control,
                           std::vector<engine::LgSlamObservation>& observations) {
  ++step_;
  control = waypoint(world_, step_) - pose_;
  parallel::RandomStream motion({seed_, step_, kMotionStream, parallel::Purpose::kSimulator});
  const double n0 = motion.normal();
  const double n1 = motion.normal();
  pose_ += control + world_.sigma_motion * Eigen::Vector2d(n0, n1);
  parallel::RandomStream sensor({seed_, step_, kSensorStream, parallel::Purpose::kSimulator});
  observations.clear();
  for (std::size_t k = 0; k < landmarks_.size(); ++k) {
    const Eigen::Vector2d offset = landmarks_[k] - pose_;
    if (offset.norm() > world_.sensor_range) continue;
    const double e0 = sensor.normal();
    const double e1 = sensor.normal();
    observations.push_back({k, offset + world_.sigma_measurement * Eigen::Vector2d(e0, e1)});
  }
}

LgSlamErrors lg_slam_errors(const engine::LgSlamFilter& filter,
                            std::span<const Eigen::Vector2d> truth_landmarks,
                            const Eigen::Vector2d& truth_pose, bool remove_offset) {
  LgSlamErrors out;
  Eigen::Vector2d offset = Eigen::Vector2d::Zero();
  std::vector<Eigen::Vector2d> diffs;
  for (std::size_t k = 0; k < truth_landmarks.size(); ++k) {
    if (!filter.mapped(k) || filter.known(k)) continue;
    diffs.push_back(filter.mean_landmark(k) - truth_landmarks[k]);
    offset += diffs.back();
  }
  out.counted = diffs.size();
  if (remove_offset && !diffs.empty()) offset /= static_cast<double>(diffs.size());
  if (!remove_offset) offset.setZero();
  double sum2 = 0.0;
  for (const Eigen::Vector2d& d : diffs) sum2 += (d - offset).squaredNorm();
  out.landmark = diffs.empty() ? std::numeric_limits<double>::quiet_NaN()
                               : std::sqrt(sum2 / static_cast<double>(diffs.size()));
  out.pose = (filter.mean_pose() - truth_pose - offset).norm();
  return out;
}

std::string_view to_string(LgSlamVariant variant) {
  return variant == LgSlamVariant::kAnchored ? "anchored" : "relative";
}

bool lg_slam_recorded_step(std::uint64_t t, std::uint64_t last) {
  if (t <= 100 || t == last) return true;
  return std::floor(50.0 * std::log10(static_cast<double>(t))) >
         std::floor(50.0 * std::log10(static_cast<double>(t - 1)));
}

std::vector<LgSlamRow> run_lg_slam_experiment(const LgSlamExperimentOptions& options) {
  if (options.seeds == 0) throw std::invalid_argument("lg-slam experiment: --seeds must be >= 1");
  if (options.particles == 0) {
    throw std::invalid_argument("lg-slam experiment: particles must be >= 1");
  }
  validate(options.world);
  const std::uint64_t steps = options.steps != 0 ? options.steps : options.tiny ? 2000 : 100'000;
  const std::uint64_t seeds =
      options.tiny ? std::min<std::uint64_t>(options.seeds, 3) : options.seeds;
  std::vector<LgSlamRow> rows;
  for (std::uint64_t s = 0; s < seeds; ++s) {
    const std::uint64_t seed = options.first_seed + s;
    for (const LgSlamVariant variant : {LgSlamVariant::kAnchored, LgSlamVariant::kRelative}) {
      run_lg_slam(options.world, variant, seed, steps, options.particles,
                  engine::LgSlamProposal::kFastSlam2,
                  [&](std::uint64_t step, const LgSlamErrors& e) {
                    if (!lg_slam_recorded_step(step, steps)) return;
                    rows.push_back({step, seed, variant, e.landmark, e.pose});
                  });
    }
  }
  return rows;
}

void write_lg_slam_csv(const std::string& path, std::span<const LgSlamRow> rows) {
  AtomicFile file(path);
  file.write("step,seed,variant,landmark_error,pose_error\n");
  char line[160];
  for (const LgSlamRow& row : rows) {
    std::snprintf(line, sizeof(line), "%llu,%llu,%s,%.9g,%.9g\n",
                  static_cast<unsigned long long>(row.step),
                  static_cast<unsigned long long>(row.seed), to_string(row.variant).data(),
                  row.landmark_error, row.pose_error);
    file.write(line);
  }
  file.commit();
}

int run_lg_slam_command(const LgSlamExperimentOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const std::vector<LgSlamRow> rows = run_lg_slam_experiment(options);
  const double run_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::filesystem::create_directories(options.out);
  const std::string path = (std::filesystem::path(options.out) / "lg_slam.csv").string();
  write_lg_slam_csv(path, rows);

  // Mean over the seeds at steps 1, 10, 100, ... and the last.
  std::uint64_t last = 0, seeds = 0;
  for (const LgSlamRow& row : rows) {
    last = std::max(last, row.step);
    if (row.step == 1 && row.variant == LgSlamVariant::kAnchored) ++seeds;
  }
  std::vector<std::uint64_t> report;
  for (std::uint64_t s = 1; s < last; s *= 10) report.push_back(s);
  report.push_back(last);
  std::printf(
      "LG-SLAM, FastSLAM 2.0, M = %zu, %zu landmarks, %llu seeds, %llu steps: mean "
      "errors over the seeds (m)\n",
      options.particles, options.world.landmarks, static_cast<unsigned long long>(seeds),
      static_cast<unsigned long long>(last));
  std::printf("%8s  %12s %12s  %12s %12s\n", "step", "anchored lm", "anchored pose", "relative lm",
              "relative pose");
  for (const std::uint64_t step : report) {
    double sums[4] = {0, 0, 0, 0};
    for (const LgSlamRow& row : rows) {
      if (row.step != step) continue;
      const int base = row.variant == LgSlamVariant::kAnchored ? 0 : 2;
      sums[base] += row.landmark_error;
      sums[base + 1] += row.pose_error;
    }
    const double n = static_cast<double>(seeds);
    std::printf("%8llu  %12.5f %12.5f  %12.5f %12.5f\n", static_cast<unsigned long long>(step),
                sums[0] / n, sums[1] / n, sums[2] / n, sums[3] / n);
  }
  std::printf("wrote %s (%zu rows) in %.2f s\n", path.c_str(), rows.size(), run_seconds);
  return 0;
}

}  // namespace fastslam::tools
