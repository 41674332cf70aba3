#include "tools/sim/simulator.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "parallel/random_stream.h"

namespace fastslam::tools {
namespace {

double wrap(double angle) {
  angle = std::remainder(angle, 2 * std::numbers::pi);
  return angle <= -std::numbers::pi ? angle + 2 * std::numbers::pi : angle;
}

// Streams of one control step: control noise and observation noise never share draws.
constexpr std::uint32_t kControlStream = 0;
constexpr std::uint32_t kSensorStream = 1;
constexpr std::uint32_t kClutterStream = 2;
constexpr std::uint32_t kDetectionStream = 3;

}  // namespace

Simulator::Simulator(const World& world, const SimConfig& config, std::uint64_t seed)
    : world_(&world),
      config_(config),
      seed_(seed),
      index_(world.landmarks),
      pose_{world.start_x, world.start_y, world.start_theta},
      loops_left_(config.loops) {
  if (world.waypoints.empty()) throw std::invalid_argument("simulator: the world has no waypoints");
  if (!(config.dt > 0) || !(config.speed > 0) || !(config.wheelbase > 0) ||
      !(config.max_range > 0) || !(config.dt_observe > 0) || !(config.field_of_view > 0) ||
      !(config.min_range > 0) || !(config.min_range < config.max_range)) {
    throw std::invalid_argument(
        "simulator: dt, speed, wheelbase, max range, field of view and observation period must "
        "be positive, and 0 < min range < max range");
  }
  if (config.sigma_v < 0 || config.sigma_steer < 0 || config.sigma_range < 0 ||
      config.sigma_bearing < 0) {
    throw std::invalid_argument("simulator: noise standard deviations must not be negative");
  }
  if (config.loops < 1) throw std::invalid_argument("simulator: loops must be at least 1");
  if (!(config.at_waypoint > 0)) {
    throw std::invalid_argument("simulator: the waypoint radius must be positive");
  }
  car_ = engine::BaileyCarModel(config.wheelbase);
  turning_radius_ = config.wheelbase / std::tan(std::max(config.max_steer, 1e-3));
  aim();
  if (!(config.clutter_rate >= 0) || !(config.clutter_rate <= 1000)) {
    throw std::invalid_argument("simulator: clutter_rate must be in [0, 1000] per scan");
  }
  if (!(config.detection_probability >= 0) || !(config.detection_probability <= 1)) {
    throw std::invalid_argument("simulator: detection_probability must be in [0, 1]");
  }
}

bool Simulator::next(SimStep& step) {
  if (done_) return false;
  // compute_steering.m: switch waypoints within at_waypoint; past the last one, start the next
  // loop or finish (the finishing step still drives and observes, as in the original).
  const Point* target = &world_->waypoints[waypoint_];
  const double d2 =
      (target->x - pose_.x) * (target->x - pose_.x) + (target->y - pose_.y) * (target->y - pose_.y);
  bool steer_update = true;
  if (d2 < config_.at_waypoint * config_.at_waypoint) {
    ++waypoint_;
    if (waypoint_ == world_->waypoints.size()) {
      steer_update = false;
      waypoint_ = 0;
      if (--loops_left_ == 0) done_ = true;
    } else {
      target = &world_->waypoints[waypoint_];
    }
    aim();
  } else {
    check_progress(d2);
  }
  if (steer_update) {
    double delta =
        wrap(std::atan2(target->y - pose_.y, target->x - pose_.x) - pose_.theta - steer_);
    const double max_delta = config_.steer_rate * config_.dt;
    if (std::abs(delta) > max_delta) delta = std::copysign(max_delta, delta);
    steer_ += delta;
    if (std::abs(steer_) > config_.max_steer) steer_ = std::copysign(config_.max_steer, steer_);
  }
  // vehicle_model.m: the engine's BaileyCarModel, the motion the filter assumes.
  const double v = config_.speed;
  const engine::BaileyCarModel::State moved =
      car_.predict({pose_.x, pose_.y, pose_.theta}, {v, steer_}, config_.dt);
  pose_ = {moved[0], moved[1], moved[2]};

  parallel::RandomStream noise({seed_, step_, kControlStream, parallel::Purpose::kSimulator});
  const double nv = noise.normal();
  const double ng = noise.normal();
  step.index = step_;
  step.dt = config_.dt;
  step.speed = v + (config_.control_noise ? nv * config_.sigma_v : 0.0);
  step.steer = steer_ + (config_.control_noise ? ng * config_.sigma_steer : 0.0);
  step.truth = pose_;

  // fastslam1_sim.m accumulates dt and observes once the sum reaches DT_OBSERVE; with dt = 0.025
  // the floating-point sum of eight steps falls just short of 0.2, so it observes every ninth
  // step. Reproduced on purpose: it is what the reference results were computed with.
  since_scan_ += config_.dt;
  step.has_scan = since_scan_ >= config_.dt_observe;
  step.scan.clear();
  if (step.has_scan) {
    since_scan_ = 0.0;
    observe(step);
  }
  ++step_;
  return true;
}

void Simulator::aim() {
  const Point& target = world_->waypoints[waypoint_];
  const double distance = std::hypot(target.x - pose_.x, target.y - pose_.y);
  // The slowest honest approach: drive the distance, turn a full circle at the tightest
  // radius, swing the steering from one stop to the other.
  const double swing = 2 * config_.max_steer / std::max(config_.steer_rate, 1e-9);
  aimed_at_ = static_cast<double>(step_) * config_.dt;
  patience_ =
      kWaypointPatience *
      ((distance + 2 * std::numbers::pi * turning_radius_) / config_.speed + swing + config_.dt);
  closest_ = distance;
}

void Simulator::check_progress(double d2) {
  const double now = static_cast<double>(step_) * config_.dt;
  closest_ = std::min(closest_, std::sqrt(d2));
  if (now - aimed_at_ <= patience_) return;
  const Point& target = world_->waypoints[waypoint_];
  char message[512];
  std::snprintf(
      message, sizeof(message),
      "simulator: waypoint %zu of %zu, at (%.2f, %.2f), not reached after %.1f s of driving "
      "(%.1f s allowed): the car came no nearer than %.2f m and must come within "
      "%.2f m. Its tightest turning circle has a radius of %.2f m, so a waypoint that "
      "near beside its path is circled, never reached. Move the waypoint, or widen "
      "the radius with --at-waypoint",
      waypoint_ + 1, world_->waypoints.size(), target.x, target.y, now - aimed_at_, patience_,
      closest_, config_.at_waypoint, turning_radius_);
  throw std::runtime_error(message);
}

double clutter_density(const SimConfig& config) {
  const double area = 0.5 * config.field_of_view *
                      (config.max_range * config.max_range - config.min_range * config.min_range);
  return area > 0 ? config.clutter_rate / area : 0.0;
}

void Simulator::observe(SimStep& step) {
  index_.within(pose_.x, pose_.y, config_.max_range, visible_);
  parallel::RandomStream noise({seed_, step_, kSensorStream, parallel::Purpose::kSimulator});
  parallel::RandomStream detect({seed_, step_, kDetectionStream, parallel::Purpose::kSimulator});
  const bool misses = config_.detection_probability < 1;
  const double half_fov = config_.field_of_view / 2;
  for (const std::uint32_t i : visible_) {
    const Point& landmark = world_->landmarks[i];
    const double dx = landmark.x - pose_.x;
    const double dy = landmark.y - pose_.y;
    const double bearing = wrap(std::atan2(dy, dx) - pose_.theta);
    // get_visible_landmarks.m keeps the half plane ahead (dx cos + dy sin > 0), i.e. |bearing|
    // < pi/2; a field of view generalises it.
    if (!(std::abs(bearing) < half_fov)) continue;
    const double range = std::sqrt(dx * dx + dy * dy);
    if (range < config_.min_range) continue;
    const double nr = noise.normal();
    const double nb = noise.normal();
    // Drawn after the noise, so a miss leaves the other detections as they were.
    if (misses && !(detect.uniform() < config_.detection_probability)) continue;
    SimObservation z;
    z.landmark = i;
    // Clamped so that a sensor never reports a range below its minimum, whatever the noise.
    z.range = std::max(config_.min_range,
                       range + (config_.sensor_noise ? nr * config_.sigma_range : 0.0));
    z.bearing = wrap(bearing + (config_.sensor_noise ? nb * config_.sigma_bearing : 0.0));
    step.scan.push_back(z);
  }
  if (config_.clutter_rate > 0) {
    // Poisson count by inversion, then points uniform in the annular sector's area.
    parallel::RandomStream clutter({seed_, step_, kClutterStream, parallel::Purpose::kSimulator});
    const double u = clutter.uniform();
    int count = 0;
    double p = std::exp(-config_.clutter_rate);
    double cumulative = p;
    while (u > cumulative && count < 10'000) {
      ++count;
      p *= config_.clutter_rate / count;
      cumulative += p;
    }
    const double r0 = config_.min_range * config_.min_range;
    const double r1 = config_.max_range * config_.max_range;
    for (int k = 0; k < count; ++k) {
      SimObservation z;
      z.landmark = kClutter;
      z.range = std::sqrt(r0 + clutter.uniform() * (r1 - r0));
      z.bearing = wrap((clutter.uniform() - 0.5) * config_.field_of_view);
      step.scan.push_back(z);
    }
  }
}

}  // namespace fastslam::tools
