#include "engine/lg_slam_filter.h"

#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "engine/lg_slam.h"
#include "engine/proposal.h"
#include "parallel/random_stream.h"
#include "parallel/resample.h"

namespace fastslam::engine {
namespace {

// P may be singular (a noise-free axis), so only symmetry and PSD are required of it.
void check_psd2(const Eigen::Matrix2d& m, const char* what) {
  const bool finite = m.allFinite();
  const double scale = finite ? m.cwiseAbs().maxCoeff() : 0.0;
  if (!finite || std::abs(m(0, 1) - m(1, 0)) > 1e-9 * scale || m(0, 0) < 0.0 || m(1, 1) < 0.0 ||
      m(0, 0) * m(1, 1) - m(0, 1) * m(1, 0) < -1e-12 * scale * scale) {
    throw std::invalid_argument(std::string(what) +
                                " must be a finite symmetric positive semidefinite 2x2 matrix");
  }
}

}  // namespace

LgSlamFilter::LgSlamFilter(const LgSlamConfig& config, const Eigen::Vector2d& initial_pose)
    : config_(config) {
  if (config.particles == 0) throw std::invalid_argument("LgSlamConfig.particles must be >= 1");
  if (config.landmarks == 0) throw std::invalid_argument("LgSlamConfig.landmarks must be >= 1");
  check_psd2(config.motion_cov, "LgSlamConfig.motion_cov");
  check_covariance2(config.measurement_cov, "LgSlamConfig.measurement_cov");
  if (!initial_pose.allFinite())
    throw std::invalid_argument("LgSlamFilter: initial pose not finite");
  mapped_.assign(config.landmarks, 0);
  poses_.assign(config.particles, initial_pose);
  maps_.assign(config.particles * config.landmarks, LandmarkGaussian{});
  log_weights_.assign(config.particles, -std::log(static_cast<double>(config.particles)));
}

void LgSlamFilter::set_known_landmark(std::size_t id, const Eigen::Vector2d& position) {
  if (id >= config_.landmarks) {
    throw std::invalid_argument("LgSlamFilter::set_known_landmark: id " + std::to_string(id) +
                                " >= landmarks " + std::to_string(config_.landmarks));
  }
  if (mapped_[id] != 0) {
    throw std::invalid_argument("LgSlamFilter::set_known_landmark: landmark " + std::to_string(id) +
                                " is already mapped");
  }
  if (!position.allFinite()) {
    throw std::invalid_argument("LgSlamFilter::set_known_landmark: position not finite");
  }
  known_id_ = id;
  mapped_[id] = 1;
  for (std::size_t i = 0; i < poses_.size(); ++i) {
    maps_[i * config_.landmarks + id] = {position, Eigen::Matrix2d::Zero()};
  }
}

void LgSlamFilter::step(const Eigen::Vector2d& u, std::span<const LgSlamObservation> observations) {
  if (!u.allFinite()) throw std::invalid_argument("LgSlamFilter::step: control not finite");
  std::vector<std::uint8_t> seen(config_.landmarks, 0);
  for (std::size_t j = 0; j < observations.size(); ++j) {
    const LgSlamObservation& obs = observations[j];
    const char* reason = obs.id >= config_.landmarks ? "landmark id >= landmarks"
                         : !obs.z.allFinite()        ? "z not finite"
                         : seen[obs.id] != 0         ? "landmark already observed in this step"
                                                     : nullptr;
    if (reason != nullptr) {
      throw std::invalid_argument("LgSlamFilter::step: observation " + std::to_string(j) +
                                  " (landmark " + std::to_string(obs.id) + "): " + reason);
    }
    seen[obs.id] = 1;
  }
  ++step_;
  const LinearGaussianMeasurement g;
  const LinearGaussianMotion h;
  const Eigen::Matrix2d& r = config_.measurement_cov;
  const std::size_t k_count = config_.landmarks;
  std::vector<std::uint8_t> mapped_now;  // per particle: mapped_ plus this scan's new ones
  for (std::size_t i = 0; i < poses_.size(); ++i) {
    LandmarkGaussian* map = &maps_[i * k_count];
    PoseGaussian<2> proposal;
    proposal.mean = h.predict(poses_[i], u, 1.0);
    proposal.cov = config_.motion_cov;
    double log_weight = 0.0;
    if (config_.proposal == LgSlamProposal::kFastSlam2) {
      for (const LgSlamObservation& obs : observations) {
        if (mapped_[obs.id] == 0) continue;
        double term = 0.0;
        proposal = fold_observation<2>(g, proposal, map[obs.id], obs.z, r, &term);
        log_weight += term;
      }
    }
    parallel::RandomStream rng(
        {config_.seed, step_, static_cast<std::uint32_t>(i), parallel::Purpose::kProposal});
    const double normals[2] = {rng.normal(), rng.normal()};
    const Eigen::Vector2d s = sample_pose<2>(proposal, normals);
    poses_[i] = s;

    mapped_now = mapped_;
    for (const LgSlamObservation& obs : observations) {
      if (obs.id == known_id_) {
        if (config_.proposal == LgSlamProposal::kMotion) {
          log_weight += evaluate_observation(g, map[obs.id], s, obs.z, r).log_likelihood;
        }
        continue;
      }
      if (mapped_now[obs.id] == 0) {
        map[obs.id] = initialize_landmark(g, s, obs.z, r);
        mapped_now[obs.id] = 1;
        continue;
      }
      const double term = update_landmark(g, map[obs.id], s, obs.z, r);
      if (config_.proposal == LgSlamProposal::kMotion && mapped_[obs.id] != 0) {
        log_weight += term;
      }
    }
    log_weights_[i] += log_weight;
  }
  for (const LgSlamObservation& obs : observations) mapped_[obs.id] = 1;
  if (poses_.size() > 1) resample();
}

void LgSlamFilter::resample() {
  std::vector<std::uint32_t> ancestors(poses_.size());
  parallel::draw_ancestors_sequential(parallel::ResampleScheme::kSystematic, log_weights_,
                                      config_.seed, step_, ancestors);
  const std::size_t k_count = config_.landmarks;
  std::vector<Eigen::Vector2d> poses(poses_.size());
  std::vector<LandmarkGaussian> maps(maps_.size());
  for (std::size_t i = 0; i < ancestors.size(); ++i) {
    poses[i] = poses_[ancestors[i]];
    for (std::size_t k = 0; k < k_count; ++k) {
      maps[i * k_count + k] = maps_[ancestors[i] * k_count + k];
    }
  }
  poses_.swap(poses);
  maps_.swap(maps);
  log_weights_.assign(poses_.size(), -std::log(static_cast<double>(poses_.size())));
}

std::vector<double> LgSlamFilter::normalised_weights() const {
  double max_log = log_weights_[0];
  for (const double l : log_weights_) max_log = std::max(max_log, l);
  std::vector<double> w(log_weights_.size());
  double sum = 0.0;
  for (std::size_t i = 0; i < w.size(); ++i) {
    w[i] = std::exp(log_weights_[i] - max_log);
    sum += w[i];
  }
  for (double& x : w) x /= sum;
  return w;
}

Eigen::Vector2d LgSlamFilter::mean_pose() const {
  if (poses_.size() == 1) return poses_[0];
  const std::vector<double> w = normalised_weights();
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < w.size(); ++i) mean += w[i] * poses_[i];
  return mean;
}

Eigen::Vector2d LgSlamFilter::mean_landmark(std::size_t id) const {
  if (poses_.size() == 1) return maps_[id].mean;
  const std::vector<double> w = normalised_weights();
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (std::size_t i = 0; i < w.size(); ++i) mean += w[i] * maps_[i * config_.landmarks + id].mean;
  return mean;
}

}  // namespace fastslam::engine
