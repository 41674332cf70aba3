#include "tools/eval/map_evaluation.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <tuple>

namespace fastslam::tools {

MapScore score_map(std::span<const engine::MapLandmark> estimate, const std::vector<Point>& truth,
                   const TruthIndex& truth_index, std::span<const bool> observed,
                   double match_radius) {
  if (!std::isfinite(match_radius) || !(match_radius > 0)) {
    throw std::invalid_argument("score_map: match radius must be finite and > 0");
  }
  if (!observed.empty() && observed.size() != truth.size()) {
    throw std::invalid_argument("score_map: one observed flag per true landmark");
  }
  struct Pair {
    double d2;
    std::uint32_t estimated;
    std::uint32_t truth;
  };
  std::vector<Pair> pairs;
  std::vector<std::uint32_t> near;
  for (std::size_t e = 0; e < estimate.size(); ++e) {
    truth_index.within(estimate[e].x, estimate[e].y, match_radius, near);
    for (std::uint32_t t : near) {
      const double dx = estimate[e].x - truth[t].x;
      const double dy = estimate[e].y - truth[t].y;
      pairs.push_back({dx * dx + dy * dy, static_cast<std::uint32_t>(e), t});
    }
  }
  std::sort(pairs.begin(), pairs.end(), [](const Pair& a, const Pair& b) {
    return std::tie(a.d2, a.estimated, a.truth) < std::tie(b.d2, b.estimated, b.truth);
  });
  std::vector<bool> estimate_used(estimate.size(), false);
  std::vector<bool> truth_used(truth.size(), false);
  MapScore score;
  double se = 0.0;
  for (const Pair& p : pairs) {
    if (estimate_used[p.estimated] || truth_used[p.truth]) continue;
    estimate_used[p.estimated] = truth_used[p.truth] = true;
    se += p.d2;
    ++score.matched;
  }
  score.rmse_m = score.matched == 0 ? 0.0 : std::sqrt(se / static_cast<double>(score.matched));
  score.spurious = estimate.size() - score.matched;
  for (std::size_t t = 0; t < truth.size(); ++t) {
    if (!truth_used[t] && (observed.empty() || observed[t])) ++score.missing;
  }
  return score;
}

}  // namespace fastslam::tools
