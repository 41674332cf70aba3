#include "tools/studies/linear_baseline.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>
#include <stdexcept>
#include <string>

#include "engine/landmark_ekf.h"
#include "parallel/random_stream.h"
#include "parallel/resample.h"

namespace fastslam::tools {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_between(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double>(b - a).count();
}

}  // namespace

LinearFastSlam::LinearFastSlam(const engine::FilterConfig& config)
    : config_(config),
      motion_(config.motion.wheelbase),
      sensor_(config.sensor.offset),
      particles_(config.particles) {
  engine::validate(config);
  if (config.algorithm != engine::Algorithm::kFastSlam1 ||
      config.association != engine::Association::kMaximumLikelihood ||
      config.motion.kind != engine::MotionKind::kBaileyCar) {
    throw std::invalid_argument(
        "linear baseline: only FastSLAM 1.0 with ML association and Bailey's car model (got " +
        std::string(engine::to_string(config.algorithm)) + ", " +
        std::string(engine::to_string(config.association)) + ", " +
        std::string(engine::to_string(config.motion.kind)) + ")");
  }
  if (config.motion_draw == engine::MotionDraw::kComposed) {
    throw std::invalid_argument(
        "linear baseline: motion_draw 'composed': it moves its particles control by control "
        "(use 'auto' or 'control')");
  }
  r_ << config.sensor.sigma_range * config.sensor.sigma_range, 0, 0,
      config.sensor.sigma_bearing * config.sensor.sigma_bearing;
  const double log_uniform = -std::log(static_cast<double>(config.particles));
  for (Particle& p : particles_) {
    p.pose = engine::Pose(config.initial_pose[0], config.initial_pose[1], config.initial_pose[2]);
    p.log_weight = log_uniform;
  }
}

double LinearFastSlam::measurement_variance(double range) const {
  return std::max(r_(0, 0), range * range * r_(1, 1));
}

void LinearFastSlam::set_map(std::span<const engine::MapLandmark> landmarks) {
  std::vector<memory::Landmark> map;
  map.reserve(landmarks.size());
  double variance_bound = landmark_variance_bound_;
  for (std::size_t k = 0; k < landmarks.size(); ++k) {
    const engine::MapLandmark& l = landmarks[k];
    auto where = [k] { return "linear baseline: set_map: landmark " + std::to_string(k) + ": "; };
    if (!std::isfinite(l.x) || !std::isfinite(l.y)) {
      throw std::invalid_argument(where() + "position must be finite");
    }
    const double det = l.sxx * l.syy - l.sxy * l.sxy;
    if (!std::isfinite(l.sxx) || !std::isfinite(l.sxy) || !std::isfinite(l.syy) || !(l.sxx > 0) ||
        !(det > 0)) {
      throw std::invalid_argument(where() + "covariance must be symmetric positive definite");
    }
    if (!std::isfinite(l.log_odds)) throw std::invalid_argument(where() + "log_odds not finite");
    const double half_trace = 0.5 * (l.sxx + l.syy);
    variance_bound = std::max(variance_bound,
                              half_trace + std::sqrt(std::max(0.0, half_trace * half_trace - det)));
    map.push_back({l.x, l.y, l.sxx, l.sxy, l.syy, l.log_odds, l.id, 0});
  }
  for (Particle& p : particles_) p.map = map;
  landmark_variance_bound_ = variance_bound;
}

void LinearFastSlam::predict(const engine::Control& control, double dt) {
  if (!std::isfinite(dt) || dt < 0 || !std::isfinite(control.u0) || !std::isfinite(control.u1)) {
    throw std::invalid_argument(
        "linear baseline: predict: dt must be finite and >= 0 and the "
        "control finite");
  }
  const Clock::time_point t0 = Clock::now();
  const engine::BaileyCarModel::Control u(control.u0, control.u1);
  const engine::BaileyCarModel::Control sigmas(config_.motion.sigma_control[0],
                                               config_.motion.sigma_control[1]);
  for (std::size_t i = 0; i < particles_.size(); ++i) {
    parallel::RandomStream stream(
        {config_.seed, step_, static_cast<std::uint32_t>(i), parallel::Purpose::kMotion});
    const double normals[2] = {stream.normal(), stream.normal()};
    particles_[i].pose = motion_.sample(particles_[i].pose, u, dt, sigmas, normals);
  }
  ++step_;
  ++stats_.controls;
  stats_.predict_seconds += seconds_between(t0, Clock::now());
}

LinearFastSlam::ScanGate LinearFastSlam::scan_gate() const {
  const engine::ExistenceConfig& ex = config_.existence;
  ScanGate g;
  g.negative = ex.negative_information && config_.sensor.max_range > ex.range_margin;
  g.view_range = config_.sensor.max_range - ex.range_margin;
  g.half_fov = 0.5 * config_.sensor.field_of_view;
  g.gate = config_.gating.gate;
  g.scale2 = config_.gating.search_scale * config_.gating.search_scale;
  return g;
}

double LinearFastSlam::associate(const Particle& p, std::span<const Eigen::Vector2d> z,
                                 const ScanGate& g, std::span<Eigen::Vector2d> at,
                                 std::span<double> radius2) {
  const std::vector<memory::Landmark>& map = p.map;
  const engine::Pose& pose = p.pose;
  const Eigen::Vector2d from = sensor_.sensor_position(pose);
  const double heading = pose[2] + sensor_.offset().yaw;
  // Candidate discs (the engine's radius: the gate under linearisation, with a margin), and
  // a box around the sensor holding every disc and the footprint, for a cheap first test.
  double reach = g.negative ? g.view_range : 0.0;
  for (std::size_t j = 0; j < z.size(); ++j) {
    at[j] = sensor_.landmark_from(z[j], pose);
    radius2[j] = g.scale2 * g.gate * (landmark_variance_bound_ + measurement_variance(z[j][0]));
    reach = std::max(reach, (at[j] - from).norm() + std::sqrt(radius2[j]));
  }
  candidates_.clear();
  in_view_.clear();
  for (std::size_t k = 0; k < map.size(); ++k) {
    const memory::Landmark& lm = map[k];
    const double dx = lm.x - from[0];
    const double dy = lm.y - from[1];
    if (std::abs(dx) > reach || std::abs(dy) > reach) continue;
    const double d2 = dx * dx + dy * dy;
    if (g.negative && d2 <= g.view_range * g.view_range &&
        std::abs(std::remainder(std::atan2(dy, dx) - heading, 2 * std::numbers::pi)) <=
            g.half_fov) {
      in_view_.push_back(static_cast<std::uint32_t>(k));
    }
    if (d2 < 1e-18) continue;  // g is undefined at the sensor
    for (std::size_t j = 0; j < z.size(); ++j) {
      const double ex2 = lm.x - at[j][0];
      const double ey2 = lm.y - at[j][1];
      if (ex2 * ex2 + ey2 * ey2 > radius2[j]) continue;
      const engine::LandmarkObservation t =
          engine::evaluate_observation(sensor_, engine::to_gaussian(lm), pose, z[j], r_);
      if (t.mahalanobis2 <= g.gate) {
        candidates_.push_back(
            {static_cast<std::uint32_t>(j), static_cast<memory::Slot>(k), t.log_likelihood});
      }
    }
  }
  return engine::associate_maximum_likelihood(candidates_, config_.log_new_landmark, assignment_);
}

void LinearFastSlam::update_map(Particle& p, std::span<const Eigen::Vector2d> z,
                                std::uint64_t scan_step) {
  const engine::ExistenceConfig& ex = config_.existence;
  std::vector<memory::Landmark>& map = p.map;
  const engine::Pose& pose = p.pose;
  touched_.clear();
  for (std::size_t j = 0; j < z.size(); ++j) {
    if (assignment_[j] == engine::kNewLandmark) continue;
    const auto slot = static_cast<std::uint32_t>(assignment_[j]);
    memory::Landmark& stored = map[slot];
    engine::LandmarkGaussian lm = engine::to_gaussian(stored);
    engine::apply_update(lm, engine::evaluate_observation(sensor_, lm, pose, z[j], r_), r_);
    engine::store_gaussian(lm, stored);
    stored.log_odds += ex.seen;
    stored.last_seen = static_cast<std::int64_t>(scan_step);
    touched_.push_back(slot);
  }
  doomed_.clear();
  for (const std::uint32_t k : in_view_) {
    if (std::find(touched_.begin(), touched_.end(), k) != touched_.end()) continue;
    map[k].log_odds -= ex.missed;
    if (map[k].log_odds < ex.remove_below) doomed_.push_back(k);
  }
  if (!doomed_.empty()) {  // doomed_ is ascending: one compaction pass keeps the order
    std::size_t out = doomed_[0], d = 0;
    for (std::size_t k = doomed_[0]; k < map.size(); ++k) {
      if (d < doomed_.size() && doomed_[d] == k) {
        ++d;
        continue;
      }
      map[out++] = map[k];
    }
    map.resize(out);
    stats_.landmarks_removed += doomed_.size();
  }
  for (std::size_t j = 0; j < z.size(); ++j) {
    if (assignment_[j] != engine::kNewLandmark) continue;
    memory::Landmark stored;
    engine::store_gaussian(engine::initialize_landmark(sensor_, pose, z[j], r_), stored);
    stored.log_odds = ex.initial;
    stored.id = scan_step * engine::kLandmarkIdsPerScan + j;
    stored.last_seen = static_cast<std::int64_t>(scan_step);
    map.push_back(stored);
    ++stats_.landmarks_created;
  }
}

void LinearFastSlam::observe(std::span<const engine::Observation> scan) {
  if (scan.size() >= engine::kLandmarkIdsPerScan) {
    throw std::invalid_argument("linear baseline: observe: too many observations in a scan");
  }
  std::vector<Eigen::Vector2d> z;
  z.reserve(scan.size());
  for (std::size_t j = 0; j < scan.size(); ++j) {
    if (!std::isfinite(scan[j].range) || !(scan[j].range > 0) || !std::isfinite(scan[j].bearing)) {
      throw std::invalid_argument("linear baseline: observe: observation " + std::to_string(j) +
                                  ": range must be finite and > 0, bearing finite");
    }
    z.emplace_back(scan[j].range, scan[j].bearing);
  }
  for (const Eigen::Vector2d& zj : z) {
    landmark_variance_bound_ = std::max(landmark_variance_bound_, measurement_variance(zj[0]));
  }
  const std::uint64_t scan_step = step_;
  const ScanGate gate = scan_gate();
  std::vector<Eigen::Vector2d> at(z.size());
  std::vector<double> radius2(z.size());
  assignment_.resize(z.size());
  for (Particle& p : particles_) {
    const Clock::time_point t0 = Clock::now();
    p.log_weight += associate(p, z, gate, at, radius2);
    const Clock::time_point t1 = Clock::now();
    update_map(p, z, scan_step);
    const Clock::time_point t2 = Clock::now();
    stats_.associate_seconds += seconds_between(t0, t1);
    stats_.update_seconds += seconds_between(t1, t2);
  }
  ++step_;
  ++stats_.scans;
  stats_.observations += scan.size();
  const Clock::time_point t0 = Clock::now();
  resample_after(scan_step);
  stats_.resample_seconds += seconds_between(t0, Clock::now());
}

void LinearFastSlam::resample_after(std::uint64_t scan_step) {
  const std::size_t m = particles_.size();
  std::vector<double> log_weight(m);
  for (std::size_t i = 0; i < m; ++i) log_weight[i] = particles_[i].log_weight;
  std::vector<std::uint32_t> ancestors(m);
  try {
    parallel::draw_ancestors_sequential(parallel::ResampleScheme::kSystematic, log_weight,
                                        config_.seed, scan_step, ancestors);
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error("linear baseline: numerical failure after scan " +
                             std::to_string(scan_step) + ": " + e.what());
  } catch (const std::domain_error&) {
    std::iota(ancestors.begin(), ancestors.end(), 0u);  // every weight zero: keep all, uniform
    ++stats_.weight_resets;
  }
  // Ancestors come sorted: the last child of a parent takes its map, the others copy it.
  std::vector<Particle> next(m);
  const double log_uniform = -std::log(static_cast<double>(m));
  for (std::size_t k = 0; k < m; ++k) {
    Particle& parent = particles_[ancestors[k]];
    next[k].pose = parent.pose;
    next[k].log_weight = log_uniform;
    if (k + 1 < m && ancestors[k + 1] == ancestors[k]) {
      next[k].map = parent.map;
      ++stats_.map_copies;
    } else {
      next[k].map = std::move(parent.map);
    }
  }
  particles_ = std::move(next);
}

engine::Pose LinearFastSlam::mean_pose() const {
  double top = -std::numeric_limits<double>::infinity();
  for (const Particle& p : particles_) top = std::max(top, p.log_weight);
  double sum = 0.0, x = 0.0, y = 0.0, c = 0.0, s = 0.0;
  for (const Particle& p : particles_) {
    const double w = std::exp(p.log_weight - top);
    sum += w;
    x += w * p.pose[0];
    y += w * p.pose[1];
    c += w * std::cos(p.pose[2]);
    s += w * std::sin(p.pose[2]);
  }
  return {x / sum, y / sum, (c == 0.0 && s == 0.0) ? 0.0 : std::atan2(s, c)};
}

std::int64_t LinearFastSlam::live_bytes() const {
  std::int64_t bytes = 0;
  for (const Particle& p : particles_) {
    bytes += static_cast<std::int64_t>(p.map.capacity() * sizeof(memory::Landmark));
  }
  return bytes;
}

}  // namespace fastslam::tools
