// ns per FastSLAM 1.0 landmark step: linearise, Q, likelihood (eq. 31-32) and, for the update,
// the Joseph-form EKF update (eq. 25). The design's budget calls this "the bare 2x2 EKF
// arithmetic, about 40 ns". BM_BareEkfFloor is that floor written out by hand (scalars, no
// checks, no Joseph form): the arithmetic any particle-observation update must do, which
// docs/scaling.md counts with callgrind against the filter's instructions per update.
#include <algorithm>
#include <cmath>

#include <benchmark/benchmark.h>

#include "bench/engine/bench_inputs.h"
#include "engine/landmark_ekf.h"

namespace fastslam::engine::bench {

// The floor of one FastSLAM 1.0 particle-observation update, in scalars: predict the range and
// bearing (sqrt, atan2), the Jacobian H, S = H P H^T + R, its inverse, the gain K = P H^T S^-1,
// the mean and the covariance (I - K H) P (symmetric, 3 unique terms) and the Gaussian
// log-likelihood (log). Not inlined, so that callgrind counts it by name
// (fastslam::engine::bench::bare_ekf_update).
[[gnu::noinline]] double bare_ekf_update(const double* pose, double* lm, const double* z,
                                         double r_range, double r_bearing) {
  const double dx = lm[0] - pose[0], dy = lm[1] - pose[1];
  const double q = dx * dx + dy * dy, d = std::sqrt(q);
  double vb = z[1] - (std::atan2(dy, dx) - pose[2]);
  vb = vb > M_PI ? vb - 2 * M_PI : vb < -M_PI ? vb + 2 * M_PI : vb;
  const double vr = z[0] - d;
  const double h00 = dx / d, h01 = dy / d, h10 = -dy / q, h11 = dx / q;
  const double p00 = lm[2], p01 = lm[3], p11 = lm[4];
  const double a00 = p00 * h00 + p01 * h01, a01 = p00 * h10 + p01 * h11;  // P H^T
  const double a10 = p01 * h00 + p11 * h01, a11 = p01 * h10 + p11 * h11;
  const double s00 = h00 * a00 + h01 * a10 + r_range, s01 = h00 * a01 + h01 * a11;
  const double s11 = h10 * a01 + h11 * a11 + r_bearing;
  const double det = s00 * s11 - s01 * s01, inv = 1.0 / det;
  const double i00 = s11 * inv, i01 = -s01 * inv, i11 = s00 * inv;
  const double k00 = a00 * i00 + a01 * i01, k01 = a00 * i01 + a01 * i11;
  const double k10 = a10 * i00 + a11 * i01, k11 = a10 * i01 + a11 * i11;
  lm[0] += k00 * vr + k01 * vb;
  lm[1] += k10 * vr + k11 * vb;
  lm[2] = p00 - (k00 * a00 + k01 * a01);  // P - K S K^T = P - K (P H^T)^T
  lm[3] = p01 - (k00 * a10 + k01 * a11);
  lm[4] = p11 - (k10 * a10 + k11 * a11);
  const double maha = vr * (i00 * vr + i01 * vb) + vb * (i01 * vr + i11 * vb);
  return -0.5 * maha - 0.5 * std::log(det) - std::log(2 * M_PI);
}

// The engine's FS1 update (update_landmark: evaluate_observation, then the Joseph-form
// apply_update), not inlined so that callgrind counts it by name next to the floor.
[[gnu::noinline]] double engine_ekf_update(const RangeBearingModel& model, LandmarkGaussian& lm,
                                           const Pose& pose, const Eigen::Vector2d& z,
                                           const Eigen::Matrix2d& r) {
  return update_landmark(model, lm, pose, z, r);
}

namespace {

void BM_BareEkfFloor(benchmark::State& state) {
  const RangeBearingModel model;
  const auto scenarios = make_scenarios(model);
  const Eigen::Matrix2d r = bailey_r();
  // The floor must compute what the engine computes: check it against update_landmark on the
  // whole ring before timing (the smoke run of tools/test.sh fails otherwise).
  for (const Scenario& s : scenarios) {
    LandmarkGaussian ref = s.lm;
    const double ll = engine_ekf_update(model, ref, s.pose, s.z, r);
    double lm[5] = {s.lm.mean[0], s.lm.mean[1], s.lm.cov(0, 0), s.lm.cov(0, 1), s.lm.cov(1, 1)};
    const double got = bare_ekf_update(s.pose.data(), lm, s.z.data(), r(0, 0), r(1, 1));
    const double err = std::max({std::abs(got - ll), std::abs(lm[0] - ref.mean[0]),
                                 std::abs(lm[1] - ref.mean[1]), std::abs(lm[2] - ref.cov(0, 0)),
                                 std::abs(lm[3] - ref.cov(0, 1)), std::abs(lm[4] - ref.cov(1, 1))});
    if (!(err < 1e-9)) {
      state.SkipWithError("bare_ekf_update disagrees with update_landmark");
      return;
    }
  }
  std::size_t i = 0;
  for (auto _ : state) {
    const Scenario& s = scenarios[i++ & (kRing - 1)];
    double lm[5] = {s.lm.mean[0], s.lm.mean[1], s.lm.cov(0, 0), s.lm.cov(0, 1), s.lm.cov(1, 1)};
    benchmark::DoNotOptimize(bare_ekf_update(s.pose.data(), lm, s.z.data(), r(0, 0), r(1, 1)));
    benchmark::DoNotOptimize(lm);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_BareEkfFloor);

// One FS1 landmark update plus its log-likelihood, from a fresh prior each time.
void BM_LandmarkEkfUpdate(benchmark::State& state) {
  const RangeBearingModel model;
  const auto scenarios = make_scenarios(model);
  const Eigen::Matrix2d r = bailey_r();
  std::size_t i = 0;
  for (auto _ : state) {
    const Scenario& s = scenarios[i++ & (kRing - 1)];
    LandmarkGaussian lm = s.lm;
    benchmark::DoNotOptimize(update_landmark(model, lm, s.pose, s.z, r));
    benchmark::DoNotOptimize(lm);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_LandmarkEkfUpdate);

// Scoring one data-association candidate: the terms without the update.
void BM_LandmarkEkfEvaluate(benchmark::State& state) {
  const RangeBearingModel model;
  const auto scenarios = make_scenarios(model);
  const Eigen::Matrix2d r = bailey_r();
  std::size_t i = 0;
  for (auto _ : state) {
    const Scenario& s = scenarios[i++ & (kRing - 1)];
    benchmark::DoNotOptimize(evaluate_observation(model, s.lm, s.pose, s.z, r).log_likelihood);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_LandmarkEkfEvaluate);

// The update alone, given the evaluated terms (what the filter pays after choosing).
void BM_LandmarkEkfApply(benchmark::State& state) {
  const RangeBearingModel model;
  const auto scenarios = make_scenarios(model);
  const Eigen::Matrix2d r = bailey_r();
  std::array<LandmarkObservation, kRing> observations;
  for (std::size_t k = 0; k < kRing; ++k) {
    observations[k] =
        evaluate_observation(model, scenarios[k].lm, scenarios[k].pose, scenarios[k].z, r);
  }
  std::size_t i = 0;
  for (auto _ : state) {
    const std::size_t k = i++ & (kRing - 1);
    LandmarkGaussian lm = scenarios[k].lm;
    apply_update(lm, observations[k], r);
    benchmark::DoNotOptimize(lm);
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_LandmarkEkfApply);

}  // namespace
}  // namespace fastslam::engine::bench
