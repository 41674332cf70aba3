// Inputs shared by the engine benchmarks: a ring of random but realistic observation scenarios
// (Bailey's simulator scales: landmarks 2..30 m away, R = diag(0.1 m, 1 deg)^2), so that every
// iteration works on fresh data the compiler cannot fold away.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <random>

#include <Eigen/Core>

#include "engine/landmark_ekf.h"
#include "engine/measurement_model.h"
#include "engine/motion_model.h"
#include "engine/proposal.h"

namespace fastslam::engine::bench {

// The motion model a benchmark runs: the model's default, and for the Ackermann car the
// Victoria Park car's geometry (../shared/data/victoria_park/README.md). Built in place, so the
// compiler sees the parameters as it does for a default-constructed model.
template <class Model>
struct BenchMotion : Model {};
template <>
struct BenchMotion<AckermannModel> : AckermannModel {
  BenchMotion() : AckermannModel(AckermannGeometry{3.78, 0.50, 2.83, 0.76}) {}
};

struct Scenario {
  Pose pose;
  LandmarkGaussian lm;
  Eigen::Vector2d z;
  PoseGaussian<3> motion;  // N(s_hat, P) of one Bailey car step
};

inline constexpr std::size_t kRing = 1024;  // a power of two: index with & (kRing - 1)

inline Eigen::Matrix2d bailey_r() {
  Eigen::Matrix2d r;
  r << 0.1 * 0.1, 0.0, 0.0, 0.01745329 * 0.01745329;
  return r;
}

inline std::array<Scenario, kRing> make_scenarios(const RangeBearingModel& model) {
  std::array<Scenario, kRing> out;
  std::mt19937_64 rng(2024);
  std::uniform_real_distribution<double> pos(-100.0, 100.0);
  std::uniform_real_distribution<double> heading(-3.14159, 3.14159);
  std::uniform_real_distribution<double> range(2.0, 30.0);
  std::uniform_real_distribution<double> sd(0.05, 1.0);
  std::normal_distribution<double> n;
  const BaileyCarModel car(4.0);
  for (Scenario& s : out) {
    s.pose = {pos(rng), pos(rng), heading(rng)};
    s.lm.mean = model.landmark_from({range(rng), heading(rng)}, s.pose);
    const double a = sd(rng), b = sd(rng);
    s.lm.cov << a * a, 0.3 * a * b, 0.3 * a * b, b * b;
    s.z = model.predict(s.lm.mean, s.pose) + Eigen::Vector2d(0.1 * n(rng), 0.017 * n(rng));
    s.z[1] = wrap_angle(s.z[1]);
    const Eigen::Vector2d u(3.0, 0.3 * n(rng));
    s.motion.mean = s.pose;
    s.motion.cov =
        car.pose_noise(s.pose, u, 0.2, BaileyCarModel::control_covariance({0.3, 0.0524}));
  }
  return out;
}

}  // namespace fastslam::engine::bench
