#include "tools/eval/map_evaluation.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>
#include <stdexcept>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::tools {
namespace {

// Oracle: the same greedy pairing over every (estimate, truth) pair, without the kd-tree.
MapScore brute_force(const std::vector<engine::MapLandmark>& estimate,
                     const std::vector<Point>& truth, const std::vector<char>& observed,
                     double radius) {
  std::vector<std::tuple<double, std::size_t, std::size_t>> pairs;
  for (std::size_t e = 0; e < estimate.size(); ++e) {
    for (std::size_t t = 0; t < truth.size(); ++t) {
      const double d2 =
          std::pow(estimate[e].x - truth[t].x, 2) + std::pow(estimate[e].y - truth[t].y, 2);
      if (d2 <= radius * radius) pairs.emplace_back(d2, e, t);
    }
  }
  std::sort(pairs.begin(), pairs.end());
  std::vector<bool> e_used(estimate.size()), t_used(truth.size());
  MapScore s;
  double se = 0.0;
  for (const auto& [d2, e, t] : pairs) {
    if (e_used[e] || t_used[t]) continue;
    e_used[e] = t_used[t] = true;
    se += d2;
    ++s.matched;
  }
  s.rmse_m = s.matched == 0 ? 0.0 : std::sqrt(se / s.matched);
  s.spurious = estimate.size() - s.matched;
  for (std::size_t t = 0; t < truth.size(); ++t) s.missing += !t_used[t] && observed[t];
  return s;
}

TEST(ScoreMap, MatchesBruteForceOnRandomMaps) {
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(0.0, 100.0), jitter(-3.0, 3.0);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<Point> truth(200);
    for (Point& p : truth) p = {u(rng), u(rng)};
    std::vector<engine::MapLandmark> estimate;
    std::vector<char> observed(truth.size());
    for (std::size_t t = 0; t < truth.size(); ++t) {
      observed[t] = rng() % 4 != 0;
      if (rng() % 3 == 0) continue;  // missed
      engine::MapLandmark l;
      l.x = truth[t].x + jitter(rng);
      l.y = truth[t].y + jitter(rng);
      estimate.push_back(l);
    }
    for (int k = 0; k < 30; ++k) {  // spurious ones
      engine::MapLandmark l;
      l.x = u(rng);
      l.y = u(rng);
      estimate.push_back(l);
    }
    const TruthIndex index(truth);
    const std::unique_ptr<bool[]> flags(new bool[truth.size()]);
    for (std::size_t t = 0; t < truth.size(); ++t) flags[t] = observed[t] != 0;
    const double radius = 2.0 + trial % 3;
    const MapScore got =
        score_map(estimate, truth, index, std::span<const bool>(flags.get(), truth.size()), radius);
    const MapScore want = brute_force(estimate, truth, observed, radius);
    EXPECT_EQ(got.matched, want.matched) << trial;
    EXPECT_EQ(got.spurious, want.spurious) << trial;
    EXPECT_EQ(got.missing, want.missing) << trial;
    EXPECT_NEAR(got.rmse_m, want.rmse_m, 1e-12) << trial;
  }
}

TEST(ScoreMap, RefusesABadRadiusOrFlagCount) {
  const std::vector<Point> truth = {{0.0, 0.0}};
  const TruthIndex index(truth);
  EXPECT_THROW(score_map({}, truth, index, {}, 0.0), std::invalid_argument);
  EXPECT_THROW(score_map({}, truth, index, {}, INFINITY), std::invalid_argument);
  const bool two[2] = {true, true};
  EXPECT_THROW(score_map({}, truth, index, two, 1.0), std::invalid_argument);
  EXPECT_EQ(score_map({}, truth, index, {}, 1.0).missing, 1u);
}

}  // namespace
}  // namespace fastslam::tools
