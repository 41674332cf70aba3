#include "tools/eval/map_metrics.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <numeric>
#include <random>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::tools {
namespace {

double distance(const Point& a, const Point& b) { return std::hypot(a.x - b.x, a.y - b.y); }

// Oracle: GOSPA^p by enumerating every partial one-to-one assignment (alpha = 2).
double brute_gospa_p(const std::vector<Point>& x, const std::vector<Point>& y, double c, double p) {
  std::vector<bool> taken(y.size(), false);
  const double half = std::pow(c, p) / 2;
  std::function<double(std::size_t)> best = [&](std::size_t i) -> double {
    if (i == x.size()) {
      return half * static_cast<double>(std::count(taken.begin(), taken.end(), false));
    }
    double b = half + best(i + 1);  // x[i] unassigned
    for (std::size_t j = 0; j < y.size(); ++j) {
      if (taken[j]) continue;
      taken[j] = true;
      b = std::min(b, std::pow(std::min(distance(x[i], y[j]), c), p) + best(i + 1));
      taken[j] = false;
    }
    return b;
  };
  return best(0);
}

// Oracle: OSPA from its own definition, every injection of the smaller set into the larger.
double brute_ospa(std::vector<Point> x, std::vector<Point> y, double c, double p) {
  if (x.empty() && y.empty()) return 0.0;
  if (x.size() > y.size()) std::swap(x, y);
  std::vector<std::size_t> perm(y.size());
  std::iota(perm.begin(), perm.end(), 0);
  double best = std::numeric_limits<double>::infinity();
  do {
    double sum = 0.0;
    for (std::size_t i = 0; i < x.size(); ++i) {
      sum += std::pow(std::min(distance(x[i], y[perm[i]]), c), p);
    }
    best = std::min(best, sum);
  } while (std::next_permutation(perm.begin(), perm.end()));
  const auto n = static_cast<double>(y.size());
  return std::pow((best + std::pow(c, p) * (n - static_cast<double>(x.size()))) / n, 1 / p);
}

// Oracle: the largest number of pairs closer than r.
std::size_t brute_max_matching(const std::vector<Point>& x, const std::vector<Point>& y, double r) {
  std::vector<bool> taken(y.size(), false);
  std::function<std::size_t(std::size_t)> best = [&](std::size_t i) -> std::size_t {
    if (i == x.size()) return 0;
    std::size_t b = best(i + 1);
    for (std::size_t j = 0; j < y.size(); ++j) {
      if (taken[j] || !(distance(x[i], y[j]) < r)) continue;
      taken[j] = true;
      b = std::max(b, 1 + best(i + 1));
      taken[j] = false;
    }
    return b;
  };
  return best(0);
}

std::vector<Point> random_points(std::mt19937_64& rng, std::size_t n, double side) {
  std::uniform_real_distribution<double> u(0.0, side);
  std::vector<Point> points(n);
  for (Point& q : points) q = {u(rng), u(rng)};
  return points;
}

Gospa gospa_of(const std::vector<Point>& estimate, const std::vector<Point>& truth, double c,
               double p, std::size_t max_exact = 2000) {
  const TruthIndex index(truth);
  return gospa(estimate, truth, index, {},
               {.cutoff = c, .order = p, .max_exact_component = max_exact});
}

TEST(Gospa, MatchesBruteForceOnSmallRandomSets) {
  std::mt19937_64 rng(17);
  for (int trial = 0; trial < 300; ++trial) {
    const std::vector<Point> x = random_points(rng, rng() % 6, 4.0);
    const std::vector<Point> y = random_points(rng, rng() % 6, 4.0);
    const double c = std::array{0.5, 1.0, 2.0, 10.0}[trial % 4];
    const double p = std::array{1.0, 2.0, 3.0}[trial % 3];
    const Gospa g = gospa_of(x, y, c, p);
    const double cp = std::pow(c, p);
    EXPECT_NEAR(std::pow(g.distance, p), brute_gospa_p(x, y, c, p), 1e-9 * cp) << trial;
    EXPECT_NEAR(std::pow(g.distance, p),
                g.localisation + cp / 2 * static_cast<double>(g.missed + g.false_targets),
                1e-9 * cp);
    EXPECT_EQ(g.missed, y.size() - g.assigned);
    EXPECT_EQ(g.false_targets, x.size() - g.assigned);
    EXPECT_NEAR(g.ospa, brute_ospa(x, y, c, p), 1e-9 * c) << trial;
    EXPECT_EQ(g.inexact_components, 0u);
  }
}

TEST(Gospa, KnownValues) {
  const std::vector<Point> truth = {{0, 0}, {5, 0}, {0, 5}, {5, 5}};
  const double c = 2.0;
  for (const double p : {1.0, 2.0}) {
    // Identical sets.
    Gospa g = gospa_of(truth, truth, c, p);
    EXPECT_EQ(g.distance, 0.0);
    EXPECT_EQ(g.ospa, 0.0);
    EXPECT_EQ(g.assigned, 4u);
    EXPECT_EQ(g.components, 4u);
    // One landmark missed: (c^p / 2)^(1/p); OSPA charges c^p over 4.
    g = gospa_of({truth.begin(), truth.end() - 1}, truth, c, p);
    EXPECT_DOUBLE_EQ(g.distance, std::pow(std::pow(c, p) / 2, 1 / p));
    EXPECT_EQ(g.missed, 1u);
    EXPECT_EQ(g.false_targets, 0u);
    EXPECT_DOUBLE_EQ(g.ospa, std::pow(std::pow(c, p) / 4, 1 / p));
    // The set shifted by s < c: every pair at s.
    const double s = 0.3;
    std::vector<Point> shifted = truth;
    for (Point& q : shifted) q.x += s;
    g = gospa_of(shifted, truth, c, p);
    EXPECT_NEAR(g.distance, std::pow(4.0, 1 / p) * s, 1e-12);
    EXPECT_NEAR(g.ospa, s, 1e-12);
    EXPECT_NEAR(g.localisation, 4 * std::pow(s, p), 1e-12);
    // Shifted past the cutoff: nothing pairs.
    for (Point& q : shifted) q.x += c;
    g = gospa_of(shifted, truth, c, p);
    EXPECT_EQ(g.assigned, 0u);
    EXPECT_DOUBLE_EQ(g.distance, std::pow(4 * std::pow(c, p), 1 / p));
    EXPECT_DOUBLE_EQ(g.ospa, c);
  }
  EXPECT_EQ(gospa_of({}, {}, c, 2).distance, 0.0);
  EXPECT_EQ(gospa_of({}, {}, c, 2).ospa, 0.0);
  EXPECT_DOUBLE_EQ(gospa_of({}, truth, c, 2).ospa, c);
}

// Nearest-first is not optimal: e1 - t1 at 0.1 blocks e0 - t1 and e1 - t2.
TEST(Gospa, ExactWhereGreedyIsNotAndCountsGreedyComponents) {
  const std::vector<Point> estimate = {{0, 0}, {1.0, 0}};
  const std::vector<Point> truth = {{0.9, 0}, {1.95, 0}};
  const Gospa exact = gospa_of(estimate, truth, 1.5, 2);
  EXPECT_EQ(exact.assigned, 2u);
  EXPECT_NEAR(exact.localisation, 0.81 + 0.9025, 1e-12);
  EXPECT_EQ(exact.largest_component, 4u);
  const Gospa greedy = gospa_of(estimate, truth, 1.5, 2, 3);
  EXPECT_EQ(greedy.inexact_components, 1u);
  EXPECT_EQ(greedy.assigned, 1u);
  EXPECT_GT(greedy.distance, exact.distance);
}

TEST(Gospa, UnobservedTruthIsNeitherMissedNorAssignable) {
  const std::vector<Point> truth = {{0, 0}, {10, 0}};
  const TruthIndex index(truth);
  const bool observed[] = {true, false};
  const Gospa g = gospa(std::vector<Point>{{10, 0.1}}, truth, index, observed, {.cutoff = 1.0});
  EXPECT_EQ(g.assigned, 0u);
  EXPECT_EQ(g.missed, 1u);
  EXPECT_EQ(g.false_targets, 1u);
  const bool wrong_size[] = {true};
  EXPECT_THROW(gospa({}, truth, index, wrong_size, {}), std::invalid_argument);
  EXPECT_THROW(gospa({}, truth, index, {}, {.cutoff = 0.0}), std::invalid_argument);
  EXPECT_THROW(gospa({}, truth, index, {}, {.order = 0.5}), std::invalid_argument);
}

TEST(PrecisionRecall, MaximumMatchingWithinTheRadius) {
  std::mt19937_64 rng(23);
  for (int trial = 0; trial < 200; ++trial) {
    const std::vector<Point> x = random_points(rng, rng() % 7, 3.0);
    const std::vector<Point> y = random_points(rng, rng() % 7, 3.0);
    const TruthIndex index(y);
    const Detection d = precision_recall(x, y, index, {}, 0.8);
    const std::size_t m = brute_max_matching(x, y, 0.8);
    EXPECT_EQ(d.matched, m) << trial;
    EXPECT_DOUBLE_EQ(d.precision, x.empty() ? 1.0 : double(m) / double(x.size()));
    EXPECT_DOUBLE_EQ(d.recall, y.empty() ? 1.0 : double(m) / double(y.size()));
  }
  // On the chain t1 - e0 - t0 - e1, GOSPA (p = 2) prefers e0 - t0 at 0.02 to two pairs at
  // 0.95; precision and recall count both.
  const std::vector<Point> estimate = {{0, 0}, {0.97, 0}};
  const std::vector<Point> truth = {{0.02, 0}, {-0.95, 0}};
  const TruthIndex index(truth);
  EXPECT_EQ(precision_recall(estimate, truth, index, {}, 1.0).matched, 2u);
  EXPECT_EQ(gospa(estimate, truth, index, {}, {.cutoff = 1.0}).assigned, 1u);
}

// 10^5 landmarks: a jittered grid 3 m apart, estimates within 0.2 m of 95% of them and 5%
// clutter; cutoff 1 m keeps the components tiny.
TEST(Gospa, ScalesToALargeMap) {
  std::mt19937_64 rng(29);
  std::uniform_real_distribution<double> jitter(-0.5, 0.5);
  std::normal_distribution<double> noise(0.0, 0.07);
  std::vector<Point> truth, estimate;
  for (int i = 0; i < 100000; ++i) {
    truth.push_back({3.0 * (i % 316) + jitter(rng), 3.0 * (i / 316) + jitter(rng)});
    if (i % 20 != 0) estimate.push_back({truth.back().x + noise(rng), truth.back().y + noise(rng)});
    if (i % 20 == 7) estimate.push_back({truth.back().x + 1.5, truth.back().y});
  }
  const TruthIndex index(truth);
  const Gospa g = gospa(estimate, truth, index, {}, {.cutoff = 1.0, .order = 2.0});
  EXPECT_EQ(g.inexact_components, 0u);
  EXPECT_EQ(g.assigned, 95000u);
  EXPECT_EQ(g.missed, 5000u);
  EXPECT_EQ(g.false_targets, 5000u);
  EXPECT_LT(g.largest_component, 20u);
  EXPECT_NEAR(std::sqrt(g.localisation / g.assigned), 0.07 * std::sqrt(2.0), 0.01);
  const Detection d = precision_recall(estimate, truth, index, {}, 0.5);
  EXPECT_EQ(d.matched, 95000u);
  EXPECT_NEAR(d.recall, 0.95, 1e-12);
}

TEST(Positions, OfAMap) {
  std::vector<engine::MapLandmark> map(2);
  map[1].x = 3.0;
  map[1].y = -1.0;
  EXPECT_EQ(positions(map), (std::vector<Point>{{0, 0}, {3, -1}}));
}

}  // namespace
}  // namespace fastslam::tools
