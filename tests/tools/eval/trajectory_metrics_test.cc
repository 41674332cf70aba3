#include "tools/eval/trajectory_metrics.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <optional>
#include <random>
#include <stdexcept>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "engine/angles.h"
#include "tools/eval/trajectory_errors.h"

namespace fastslam::tools {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

struct Streams {
  std::vector<StampedPose> estimate;
  std::vector<StampedPose> reference;
};

// A curving drive: truth every `reference_dt` s, the estimate every 0.025 s with a slowly
// growing drift, noise and a few holes wider than kMaxInterpolationGap.
Streams make_streams(std::uint64_t seed, double duration, double reference_dt) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> noise(0.0, 0.05);
  auto truth = [](double t) {
    return StampedPose{t, 20 * std::sin(0.05 * t) + 0.3 * t, 15 * std::cos(0.03 * t) - 15,
                       engine::wrap_angle(0.2 * t)};
  };
  Streams s;
  for (double t = 0.0; t <= duration; t += 0.025) {
    if (std::fmod(t, 37.0) > 35.5) continue;  // a 1.5 s hole every 37 s
    StampedPose p = truth(t);
    p.x += 0.01 * t + noise(rng);
    p.y -= 0.005 * t + noise(rng);
    p.theta = engine::wrap_angle(p.theta + 0.002 * t + noise(rng));
    s.estimate.push_back(p);
  }
  for (double t = -0.5; t <= duration + 2.0; t += reference_dt) s.reference.push_back(truth(t));
  return s;
}

// Feeds references as the source would (ahead of the filter) and estimates in batches every
// `batch` s, each batch after the references up to its end.
TrajectoryEvaluator feed_in_batches(const Streams& s, const TrajectoryEvaluatorOptions& options,
                                    double batch, std::size_t* max_buffered = nullptr) {
  TrajectoryEvaluator ev(options);
  std::size_t r = 0, e = 0;
  for (double until = batch; e < s.estimate.size(); until += batch) {
    while (r < s.reference.size() && s.reference[r].time <= until)
      ev.add_reference(s.reference[r++]);
    while (e < s.estimate.size() && s.estimate[e].time <= until) ev.add_estimate(s.estimate[e++]);
    if (max_buffered) *max_buffered = std::max(*max_buffered, ev.buffered_estimates());
  }
  while (r < s.reference.size()) ev.add_reference(s.reference[r++]);
  return ev;
}

void expect_relative(double a, double b, double tolerance) {
  EXPECT_NEAR(a, b, tolerance * std::max(1.0, std::abs(b))) << a << " vs " << b;
}

TEST(TrajectoryEvaluator, EqualsTheBatchErrorsWhenEstimatesTrailReferences) {
  for (const bool heading : {true, false}) {
    const Streams s = make_streams(7, 300.0, 0.1);
    std::size_t max_buffered = 0;
    const TrajectoryMetrics m =
        feed_in_batches(s, {.reference_heading = heading}, 0.5, &max_buffered).finish();
    const PositionErrors batch = position_errors(s.estimate, s.reference);
    EXPECT_EQ(m.raw.used, batch.used);
    EXPECT_EQ(m.raw.skipped, batch.skipped);
    EXPECT_GT(m.raw.skipped, 20u);  // before, after and in the holes
    EXPECT_NEAR(m.raw.rmse, batch.rmse, 1e-12 * batch.rmse);
    EXPECT_EQ(m.raw.last, batch.last);
    const AlignedErrors aligned = aligned_position_errors(s.estimate, s.reference);
    EXPECT_NEAR(m.aligned.rmse, aligned.rmse, 1e-10 * aligned.rmse);
    EXPECT_NEAR(m.aligned.rotation, aligned.rotation, 1e-12);
    // Memory: a batch (20 samples) plus max_reference_delay (40), never the 12000 samples.
    EXPECT_LE(max_buffered, 64u);
  }
}

TEST(TrajectoryEvaluator, AnyArrivalOrderWithinTheContractGivesTheSameNumbers) {
  const Streams s = make_streams(11, 120.0, 0.25);
  const TrajectoryMetrics batched = feed_in_batches(s, {}, 2.0).finish();
  // Every reference first: all pending until the estimates come.
  TrajectoryEvaluator refs_first({});
  for (const StampedPose& r : s.reference) refs_first.add_reference(r);
  EXPECT_EQ(refs_first.pending_references(), s.reference.size());
  for (const StampedPose& e : s.estimate) refs_first.add_estimate(e);
  // Every estimate first: only allowed with an unbounded delay.
  TrajectoryEvaluator estimates_first({.max_reference_delay = kInfinity});
  for (const StampedPose& e : s.estimate) estimates_first.add_estimate(e);
  for (const StampedPose& r : s.reference) estimates_first.add_reference(r);
  for (const TrajectoryEvaluator* ev : {&refs_first, &estimates_first}) {
    const TrajectoryMetrics m = ev->finish();
    EXPECT_EQ(m.raw.used, batched.raw.used);
    EXPECT_EQ(m.raw.skipped, batched.raw.skipped);
    EXPECT_EQ(m.raw.rmse, batched.raw.rmse);
    EXPECT_EQ(m.aligned.rmse, batched.aligned.rmse);
    EXPECT_EQ(m.rpe.pairs, batched.rpe.pairs);
    EXPECT_EQ(m.rpe.translation_rmse, batched.rpe.translation_rmse);
  }
  // With the default delay, a reference 30 s behind the estimates cannot be paired any more.
  TrajectoryEvaluator late({});
  for (const StampedPose& e : s.estimate) late.add_estimate(e);
  EXPECT_THROW(late.add_reference(s.reference[5]), std::logic_error);
}

TEST(TrajectoryEvaluator, FinishPairsPendingReferencesAndCanBeCalledAgain) {
  TrajectoryEvaluator ev({});
  ev.add_estimate({0.0, 0.0, 0.0, 0.0});
  ev.add_estimate({1.0, 1.0, 0.0, 0.0});
  ev.add_reference({1.0, 1.0, 3.0, 0.0});  // exact stamp of the newest sample: pending
  ev.add_reference({1.5, 0.5, 1.0, 0.0});  // past the estimate: skipped at the end
  EXPECT_EQ(ev.pending_references(), 2u);
  TrajectoryMetrics m = ev.finish();
  EXPECT_EQ(m.raw.used, 1u);
  EXPECT_EQ(m.raw.skipped, 1u);
  EXPECT_DOUBLE_EQ(m.raw.last, 3.0);
  ev.add_estimate({1.0, 1.0, 2.0, 0.0});  // a later sample with the same stamp wins
  ev.add_estimate({2.0, 0.0, 0.0, 0.0});
  m = ev.finish();
  EXPECT_EQ(m.raw.used, 2u);
  EXPECT_EQ(m.raw.skipped, 0u);
  EXPECT_DOUBLE_EQ(m.raw.rmse, std::sqrt(0.5));  // errors 1 and 0 (halfway to (0, 0))
  EXPECT_DOUBLE_EQ(m.raw_max, 1.0);
  EXPECT_DOUBLE_EQ(m.raw_mean, 0.5);
}

// Oracle: a reference that is the estimate moved rigidly aligns back with no error, and the
// transform found is the one applied.
TEST(TrajectoryEvaluator, RecoversARigidMotion) {
  const Streams s = make_streams(3, 60.0, 0.2);
  const double angle = -2.5, c = std::cos(angle), sn = std::sin(angle);
  std::vector<StampedPose> reference;
  for (const StampedPose& r : s.reference) {
    if (const std::optional<StampedPose> p = pose_at(s.estimate, r.time)) {
      reference.push_back({r.time, c * p->x - sn * p->y + 40.0, sn * p->x + c * p->y - 7.0,
                           engine::wrap_angle(p->theta + angle)});
    }
  }
  const TrajectoryMetrics m = feed_in_batches({s.estimate, reference}, {}, 1.0).finish();
  EXPECT_GT(m.raw.rmse, 10.0);
  // Streaming leaves sqrt(eps x spread) of rounding when the alignment removes a large error.
  EXPECT_NEAR(m.aligned.rmse, 0.0, 1e-5);
  EXPECT_NEAR(m.aligned.rotation, angle, 1e-12);
  EXPECT_NEAR(m.aligned.x, 40.0, 1e-9);
  EXPECT_NEAR(m.aligned.y, -7.0, 1e-9);
  EXPECT_NEAR(m.rpe.translation_rmse, 0.0, 1e-9);  // relative motion is frame-free
  EXPECT_NEAR(*m.rpe.rotation_rmse, 0.0, 1e-12);
}

// Oracle: the alignment by scanning the angle (translation in closed form for each angle),
// then a golden-section refinement, against the closed form.
TEST(TrajectoryEvaluator, AlignmentMatchesAnAngleScan) {
  const Streams s = make_streams(5, 200.0, 0.5);
  std::vector<std::array<double, 4>> pairs;
  for (const StampedPose& r : s.reference) {
    if (const std::optional<StampedPose> p = pose_at(s.estimate, r.time)) {
      pairs.push_back({p->x, p->y, r.x, r.y});
    }
  }
  auto rms = [&](double a) {
    const double c = std::cos(a), sn = std::sin(a);
    double tx = 0, ty = 0;
    for (const auto& [ex, ey, rx, ry] : pairs)
      tx += rx - (c * ex - sn * ey), ty += ry - (sn * ex + c * ey);
    tx /= pairs.size(), ty /= pairs.size();
    double se = 0;
    for (const auto& [ex, ey, rx, ry] : pairs) {
      se += std::pow(c * ex - sn * ey + tx - rx, 2) + std::pow(sn * ex + c * ey + ty - ry, 2);
    }
    return std::sqrt(se / pairs.size());
  };
  double best = 0, best_rms = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 20000; ++i) {
    const double a = -std::numbers::pi + 2 * std::numbers::pi * i / 20000;
    if (rms(a) < best_rms) best_rms = rms(a), best = a;
  }
  double lo = best - 4e-4, hi = best + 4e-4;
  const double g = (std::sqrt(5.0) - 1) / 2;
  for (int i = 0; i < 100; ++i) {
    const double a = hi - g * (hi - lo), b = lo + g * (hi - lo);
    (rms(a) < rms(b) ? hi : lo) = (rms(a) < rms(b) ? b : a);
  }
  const TrajectoryMetrics m = feed_in_batches(s, {}, 0.5).finish();
  EXPECT_NEAR(m.aligned.rotation, 0.5 * (lo + hi), 1e-7);
  EXPECT_NEAR(m.aligned.rmse, rms(0.5 * (lo + hi)), 1e-10);
  EXPECT_GT(m.raw.rmse, m.aligned.rmse);
}

using Matrix = std::array<std::array<double, 3>, 3>;
Matrix se2(double x, double y, double theta) {
  return {
      {{std::cos(theta), -std::sin(theta), x}, {std::sin(theta), std::cos(theta), y}, {0, 0, 1}}};
}
Matrix inverse(const Matrix& m) {
  const double x = m[0][2], y = m[1][2];
  return {{{m[0][0], m[1][0], -(m[0][0] * x + m[1][0] * y)},
           {m[0][1], m[1][1], -(m[0][1] * x + m[1][1] * y)},
           {0, 0, 1}}};
}
Matrix operator*(const Matrix& a, const Matrix& b) {
  Matrix c{};
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      for (int k = 0; k < 3; ++k) c[i][j] += a[i][k] * b[k][j];
  return c;
}

// Oracle: evo's RPE over the whole lists: the synchronised pairs, filter_pairs_by_path, then
// E = (Qi^-1 Qj)^-1 (Pi^-1 Pj) as 3 x 3 matrices.
TEST(TrajectoryEvaluator, RelativePoseErrorsMatchExplicitMatrices) {
  for (const double delta : {1.0, 10.0}) {
    const Streams s = make_streams(13, 300.0, 0.1);
    std::vector<std::pair<StampedPose, StampedPose>> synced;  // estimate, reference
    for (const StampedPose& r : s.reference) {
      if (const std::optional<StampedPose> p = pose_at(s.estimate, r.time))
        synced.push_back({*p, r});
    }
    std::vector<std::size_t> ids;
    double path = 0.0;
    for (std::size_t i = 0; i < synced.size(); ++i) {
      const StampedPose& q = synced[i].second;
      const StampedPose& prev = synced[i == 0 ? 0 : i - 1].second;
      path += std::sqrt((q.x - prev.x) * (q.x - prev.x) + (q.y - prev.y) * (q.y - prev.y));
      if (path >= delta) ids.push_back(i), path = 0.0;
    }
    const AlignedErrors aligned = aligned_position_errors(s.estimate, s.reference);
    const double c = std::cos(aligned.rotation), sn = std::sin(aligned.rotation);
    double trans = 0, rot = 0, trans_positions = 0;
    for (std::size_t k = 0; k + 1 < ids.size(); ++k) {
      const auto& [pi, qi] = synced[ids[k]];
      const auto& [pj, qj] = synced[ids[k + 1]];
      const Matrix e = inverse(inverse(se2(qi.x, qi.y, qi.theta)) * se2(qj.x, qj.y, qj.theta)) *
                       (inverse(se2(pi.x, pi.y, pi.theta)) * se2(pj.x, pj.y, pj.theta));
      trans += e[0][2] * e[0][2] + e[1][2] * e[1][2];
      rot += std::pow(std::atan2(e[1][0], e[0][0]), 2);
      const double dx = pj.x - pi.x, dy = pj.y - pi.y;
      trans_positions += std::pow(c * dx - sn * dy - (qj.x - qi.x), 2) +
                         std::pow(sn * dx + c * dy - (qj.y - qi.y), 2);
    }
    const double pairs = static_cast<double>(ids.size() - 1);
    ASSERT_GT(pairs, 10);
    const TrajectoryMetrics m = feed_in_batches(s, {.rpe_delta = delta}, 0.5).finish();
    EXPECT_EQ(m.rpe.pairs, ids.size() - 1);
    expect_relative(m.rpe.translation_rmse, std::sqrt(trans / pairs), 1e-12);
    expect_relative(*m.rpe.rotation_rmse, std::sqrt(rot / pairs), 1e-12);
    const TrajectoryMetrics gps =
        feed_in_batches(s, {.reference_heading = false, .rpe_delta = delta}, 0.5).finish();
    EXPECT_EQ(gps.rpe.pairs, ids.size() - 1);
    EXPECT_FALSE(gps.rpe.rotation_rmse);
    expect_relative(gps.rpe.translation_rmse, std::sqrt(trans_positions / pairs), 1e-10);
  }
}

// Hand case: a straight drive at 1 m/s whose estimate runs 10% long. References every 1 m,
// delta 10 m: evo's anchors are at 10, 20, ..., 100 m (9 pairs), each 1 m too long.
TEST(TrajectoryEvaluator, KnownRelativeErrorOfAStretchedPath) {
  TrajectoryEvaluator ev({.rpe_delta = 10.0});
  for (int i = 0; i <= 100; ++i) {
    ev.add_reference({double(i), double(i), 0.0, 0.0});
    ev.add_estimate({double(i), 1.1 * i, 0.0, 0.0});
  }
  const TrajectoryMetrics m = ev.finish();
  EXPECT_EQ(m.rpe.pairs, 9u);
  EXPECT_NEAR(m.rpe.translation_rmse, 1.0, 1e-12);
  EXPECT_EQ(*m.rpe.rotation_rmse, 0.0);
  EXPECT_NEAR(m.raw_max, 10.0, 1e-12);
  EXPECT_NEAR(m.raw.last, 10.0, 1e-12);
}

TEST(TrajectoryEvaluator, RefusesBadOptionsAndOutOfOrderInput) {
  EXPECT_THROW(TrajectoryEvaluator({.rpe_delta = 0.0}), std::invalid_argument);
  EXPECT_THROW(TrajectoryEvaluator({.max_reference_delay = -1.0}), std::invalid_argument);
  TrajectoryEvaluator ev({.reference_heading = false});
  ev.add_estimate({1.0, 0.0, 0.0, 0.0});
  EXPECT_THROW(ev.add_estimate({0.5, 0.0, 0.0, 0.0}), std::invalid_argument);
  EXPECT_THROW(ev.add_estimate({2.0, kNaN, 0.0, 0.0}), std::invalid_argument);
  ev.add_reference({1.0, 0.0, 0.0, kNaN});  // a GPS fix's heading is not read
  EXPECT_THROW(ev.add_reference({0.9, 0.0, 0.0, 0.0}), std::invalid_argument);
  const TrajectoryMetrics empty = TrajectoryEvaluator({}).finish();
  EXPECT_EQ(empty.raw.used, 0u);
  EXPECT_EQ(empty.aligned.rmse, 0.0);
  EXPECT_EQ(empty.rpe.pairs, 0u);
}

}  // namespace
}  // namespace fastslam::tools
