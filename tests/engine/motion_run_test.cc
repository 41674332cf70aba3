// Tests of engine/motion_run.h: each odometry model is equivariant under rigid motions (what
// lets a run be composed once for every particle); a run's mean and covariance against a Monte
// Carlo of the draw per control (the oracle) with sound statistical bounds; the rule that ends
// runs; apply_run against the scalar composition s (+) d; FastSLAM 2.0's prior over a run
// against the prediction control by control.
#include "engine/motion_run.h"

#include <cmath>
#include <cstddef>
#include <numbers>
#include <random>
#include <vector>

#include <Eigen/Core>
#include <gtest/gtest.h>

#include "engine/angles.h"
#include "engine/motion_model.h"

namespace fastslam::engine {
namespace {

using Vec3 = Eigen::Vector3d;

// s (+) d: d, given in the frame of s, expressed in the world.
Vec3 compose(const Vec3& s, const Vec3& d) {
  const double c = std::cos(s[2]);
  const double sn = std::sin(s[2]);
  return {s[0] + c * d[0] - sn * d[1], s[1] + sn * d[0] + c * d[1], wrap_angle(s[2] + d[2])};
}

// The three odometry models with controls and noises of the data sets they serve: Bailey's
// webmap (40 Hz), UTIAS MRCLAM (50 Hz), Victoria Park's car (sensor ahead and aside).
struct Case {
  const char* name;
  int kind;  // 0 bailey-car, 1 unicycle, 2 ackermann
  double u0, u1, dt, sigma0, sigma1;
  std::size_t controls;
};
const Case kCases[] = {
    {"bailey-car", 0, 3.0, 0.2, 0.025, 0.3, 3.0 * std::numbers::pi / 180, 8},
    {"unicycle", 1, 0.08, 0.4, 0.02, 0.0509, 0.132, 50},
    {"ackermann", 2, 2.5, -0.1, 0.025, 0.5, 2.0 * std::numbers::pi / 180, 10},
};

template <class F>
void with_model(int kind, F&& f) {
  if (kind == 0) {
    f(BaileyCarModel(4.0));
  } else if (kind == 1) {
    f(UnicycleModel());
  } else {
    f(AckermannModel(AckermannGeometry{3.78, 0.5, 2.83, 0.76}));
  }
}

TEST(MotionRun, OdometryModelsAreEquivariant) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> pos(-50, 50), ang(-3.1, 3.1);
  for (const Case& c : kCases) {
    with_model(c.kind, [&](const auto& model) {
      for (int i = 0; i < 200; ++i) {
        const Vec3 s(pos(rng), pos(rng), ang(rng));
        const Eigen::Vector2d u(c.u0 * (1 + 0.3 * ang(rng)), c.u1 * (1 + 0.3 * ang(rng)));
        const Vec3 at_s = model.predict(s, u, c.dt);
        const Vec3 via_origin = compose(s, model.predict(Vec3::Zero(), u, c.dt));
        EXPECT_NEAR(at_s[0], via_origin[0], 1e-12) << c.name;
        EXPECT_NEAR(at_s[1], via_origin[1], 1e-12) << c.name;
        EXPECT_NEAR(angle_diff(at_s[2], via_origin[2]), 0.0, 1e-12) << c.name;
      }
    });
  }
}

// The draw per control from the origin, n times: the sample mean and covariance of the end pose
// against the run's mean and F F^T. Bounds: the mean within 5 standard errors of the sample
// (sqrt(C_ii / n)) plus the first order's bias, 5 % of the spread (the car's steering noise
// shortens the mean path by the factor E cos(n) = exp(-sigma^2 / 2): 0.8 mm in 0.6 m, 4 % of
// the along-track spread, with the webmap's noises); each covariance
// entry within 5 standard errors (sqrt((C_ii C_jj + C_ij^2) / n), Gaussian fourth moments) plus
// 3 % of sqrt(C_ii C_jj) for the nonlinearity.
TEST(MotionRun, MeanAndCovarianceMatchTheDrawPerControl) {
  constexpr int kSamples = 100000;
  for (const Case& c : kCases) {
    with_model(c.kind, [&](const auto& model) {
      using Model = std::decay_t<decltype(model)>;
      const typename Model::Control sigmas(c.sigma0, c.sigma1);
      std::vector<ControlStep> steps(c.controls, ControlStep{c.u0, c.u1, c.dt});
      std::vector<MotionRun> runs;
      std::vector<Vec3> partial;
      compose_runs(model, steps, sigmas, runs, partial);
      ASSERT_EQ(runs.size(), 1U) << c.name;
      const Eigen::Matrix3d cov = runs[0].factor * runs[0].factor.transpose();
      std::mt19937_64 rng(11);
      std::normal_distribution<double> normal;
      Vec3 sum = Vec3::Zero();
      Eigen::Matrix3d sum2 = Eigen::Matrix3d::Zero();
      for (int i = 0; i < kSamples; ++i) {
        Vec3 s = Vec3::Zero();
        for (const ControlStep& step : steps) {
          const double n[2] = {normal(rng), normal(rng)};
          s = model.sample(s, typename Model::Control(step.u0, step.u1), step.dt, sigmas, n);
        }
        const Vec3 e = s - runs[0].mean;
        sum += e;
        sum2 += e * e.transpose();
      }
      const Vec3 bias = sum / kSamples;
      const Eigen::Matrix3d sample_cov = sum2 / kSamples - bias * bias.transpose();
      for (int i = 0; i < 3; ++i) {
        const double se = std::sqrt(cov(i, i) / kSamples);
        EXPECT_LE(std::abs(bias[i]), 5 * se + 0.05 * std::sqrt(cov(i, i))) << c.name << " " << i;
        for (int j = 0; j < 3; ++j) {
          const double scale = std::sqrt(cov(i, i) * cov(j, j));
          const double se2 = std::sqrt((cov(i, i) * cov(j, j) + cov(i, j) * cov(i, j)) / kSamples);
          EXPECT_NEAR(sample_cov(i, j), cov(i, j), 5 * se2 + 0.03 * scale)
              << c.name << " (" << i << ", " << j << ")";
        }
      }
      // The means after each control are the noise-free path.
      Vec3 s = Vec3::Zero();
      for (std::size_t k = 0; k < steps.size(); ++k) {
        s = model.predict(s, typename Model::Control(c.u0, c.u1), c.dt);
        EXPECT_NEAR((partial[k] - s).norm(), 0.0, 1e-12) << c.name << " " << k;
      }
    });
  }
}

TEST(MotionRun, RunsEndAtTheirLengthOrHeadingSpread) {
  const UnicycleModel model;
  std::vector<MotionRun> runs;
  std::vector<Vec3> partial;
  // Quiet controls: only the length ends a run (64, 64, 22), and each restarts from the origin.
  std::vector<ControlStep> steps(150, ControlStep{0.1, 0.2, 0.02});
  compose_runs(model, steps, UnicycleModel::Control(0.01, 0.01), runs, partial);
  ASSERT_EQ(runs.size(), 3U);
  EXPECT_EQ(runs[0].first, 0U);
  EXPECT_EQ(runs[0].count, kRunMaxControls);
  EXPECT_EQ(runs[1].first, kRunMaxControls);
  EXPECT_EQ(runs[2].count, 150 - 2 * kRunMaxControls);
  EXPECT_NEAR(partial[kRunMaxControls][2], 0.2 * 0.02, 1e-15);
  // omega sigma 1 rad/s at 50 Hz: heading variance 4e-4 per control, so the run ends at the
  // control that brings it to 0.0025, the 7th (2.8e-3 >= 2.5e-3).
  compose_runs(model, steps, UnicycleModel::Control(0.01, 1.0), runs, partial);
  EXPECT_EQ(runs[0].count, 7U);
  for (const MotionRun& r : runs) {
    const Eigen::Matrix3d cov = r.factor * r.factor.transpose();
    EXPECT_LE(cov(2, 2), kRunHeadingVariance * (1 + 1e-12) + 4e-4);
  }
  // No controls: no runs.
  compose_runs(model, std::span<const ControlStep>(), UnicycleModel::Control(0.01, 1.0), runs,
               partial);
  EXPECT_TRUE(runs.empty());
}

TEST(MotionRun, ApplyRunIsTheComposition) {
  const BaileyCarModel model(4.0);
  std::vector<ControlStep> steps(8, ControlStep{3.0, 0.3, 0.025});
  std::vector<MotionRun> runs;
  std::vector<Vec3> partial;
  compose_runs(model, steps, BaileyCarModel::Control(0.3, 0.05), runs, partial);
  ASSERT_EQ(runs.size(), 1U);
  constexpr std::size_t kLanes = 16;
  std::mt19937_64 rng(5);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> ang(-std::numbers::pi, std::numbers::pi);
  double x[kLanes], y[kLanes], theta[kLanes], n0[kLanes], n1[kLanes], n2[kLanes];
  std::vector<Vec3> start(kLanes);
  for (std::size_t l = 0; l < kLanes; ++l) {
    x[l] = 10 * normal(rng);
    y[l] = 10 * normal(rng);
    theta[l] = l == 0 ? std::numbers::pi : ang(rng);  // pi plus a turn wraps
    n0[l] = normal(rng);
    n1[l] = normal(rng);
    n2[l] = normal(rng);
    start[l] = Vec3(x[l], y[l], theta[l]);
  }
  apply_run(runs[0], kLanes, x, y, theta, n0, n1, n2);
  for (std::size_t l = 0; l < kLanes; ++l) {
    const Vec3 d = runs[0].mean + runs[0].factor * Vec3(n0[l], n1[l], n2[l]);
    const Vec3 want = compose(start[l], d);
    EXPECT_NEAR(x[l], want[0], 1e-12);
    EXPECT_NEAR(y[l], want[1], 1e-12);
    EXPECT_NEAR(theta[l], want[2], 1e-12);
    EXPECT_GT(theta[l], -std::numbers::pi);
    EXPECT_LE(theta[l], std::numbers::pi);
  }
}

// FastSLAM 2.0's prior over a run against the prediction control by control in the world frame
// (mean by predict, covariance by J P J^T + V M V^T at the particle's own mean path), from
// random start poses and covariances: equal up to rounding.
TEST(MotionRun, PredictRunIsThePredictionControlByControl) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> ang(-std::numbers::pi, std::numbers::pi);
  for (const Case& c : kCases) {
    with_model(c.kind, [&](const auto& model) {
      using Model = std::decay_t<decltype(model)>;
      const typename Model::Control sigmas(c.sigma0, c.sigma1);
      const typename Model::ControlCovariance m = Model::control_covariance(sigmas);
      std::vector<ControlStep> steps;
      for (std::size_t k = 0; k < c.controls; ++k) {
        steps.push_back({c.u0 * (1 + 0.2 * normal(rng)), c.u1 * (1 + 0.2 * normal(rng)), c.dt});
      }
      std::vector<MotionRun> runs;
      std::vector<Vec3> partial;
      compose_runs(model, steps, sigmas, runs, partial);
      ASSERT_EQ(runs.size(), 1U) << c.name;
      constexpr std::size_t kLanes = 8;
      double x[kLanes], y[kLanes], theta[kLanes];
      double cols[6][kLanes];
      double* p[6] = {cols[0], cols[1], cols[2], cols[3], cols[4], cols[5]};
      std::vector<Vec3> want_mean(kLanes);
      std::vector<Eigen::Matrix3d> want_cov(kLanes);
      for (std::size_t l = 0; l < kLanes; ++l) {
        Vec3 s(10 * normal(rng), 10 * normal(rng), ang(rng));
        Eigen::Matrix3d a = Eigen::Matrix3d::Zero();
        if (l % 2 == 1) {  // half start from a covariance, half from zero (after a scan)
          for (int i = 0; i < 3; ++i) {
            for (int j = 0; j < 3; ++j) a(i, j) = 0.1 * normal(rng);
          }
        }
        Eigen::Matrix3d cov = a * a.transpose();
        x[l] = s[0];
        y[l] = s[1];
        theta[l] = s[2];
        const int index[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
        for (int e = 0; e < 6; ++e) cols[e][l] = cov(index[e][0], index[e][1]);
        for (const ControlStep& step : steps) {
          const typename Model::Control u(step.u0, step.u1);
          const Eigen::Matrix3d j = model.jacobian_pose(s, u, step.dt);
          cov = j * cov * j.transpose() + model.pose_noise(s, u, step.dt, m);
          s = model.predict(s, u, step.dt);
        }
        want_mean[l] = s;
        want_cov[l] = cov;
      }
      predict_run_covariance(runs[0], kLanes, theta, p);
      apply_run_mean(runs[0], kLanes, x, y, theta);
      for (std::size_t l = 0; l < kLanes; ++l) {
        EXPECT_NEAR(x[l], want_mean[l][0], 1e-12 * (1 + std::abs(x[l]))) << c.name;
        EXPECT_NEAR(y[l], want_mean[l][1], 1e-12 * (1 + std::abs(y[l]))) << c.name;
        EXPECT_NEAR(angle_diff(theta[l], want_mean[l][2]), 0.0, 1e-12) << c.name;
        const int index[6][2] = {{0, 0}, {0, 1}, {0, 2}, {1, 1}, {1, 2}, {2, 2}};
        const double scale = want_cov[l].cwiseAbs().maxCoeff();
        for (int e = 0; e < 6; ++e) {
          EXPECT_NEAR(cols[e][l], want_cov[l](index[e][0], index[e][1]), 1e-12 * scale)
              << c.name << " lane " << l << " entry " << e;
        }
      }
    });
  }
}

}  // namespace
}  // namespace fastslam::engine
