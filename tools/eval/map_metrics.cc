#include "tools/eval/map_metrics.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <stdexcept>

namespace fastslam::tools {
namespace {

struct Edge {
  std::uint32_t estimate;
  std::uint32_t truth;
  double d;
};

struct Matching {
  std::vector<Edge> pairs;
  std::size_t components = 0, largest = 0, inexact = 0;
};

// Union-find over estimates [0, E) and truths [E, E + T): union by size, path halving.
class DisjointSets {
 public:
  explicit DisjointSets(std::size_t n) : parent_(n), size_(n, 1) {
    std::iota(parent_.begin(), parent_.end(), std::uint32_t{0});
  }
  std::uint32_t find(std::uint32_t x) {
    while (parent_[x] != x) x = parent_[x] = parent_[parent_[x]];
    return x;
  }
  void unite(std::uint32_t a, std::uint32_t b) {
    a = find(a), b = find(b);
    if (a == b) return;
    if (size_[a] < size_[b]) std::swap(a, b);
    parent_[b] = a;
    size_[a] += size_[b];
  }

 private:
  std::vector<std::uint32_t> parent_, size_;
};

// Minimum-cost assignment of every row of the rows x cols matrix `a` (rows <= cols) to its own
// column: the Hungarian method with potentials (Kuhn-Munkres, the O(n^2 m) form of Jonker-
// Volgenant's shortest augmenting paths). Returns the row of each column, -1 if none.
std::vector<int> hungarian(const std::vector<double>& a, int rows, int cols) {
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> u(rows + 1, 0.0), v(cols + 1, 0.0), min_slack(cols + 1);
  std::vector<int> row_of(cols + 1, 0), way(cols + 1, 0);
  std::vector<char> used(cols + 1);
  for (int i = 1; i <= rows; ++i) {
    row_of[0] = i;
    int j0 = 0;
    std::fill(min_slack.begin(), min_slack.end(), inf);
    std::fill(used.begin(), used.end(), 0);
    do {
      used[j0] = 1;
      const int i0 = row_of[j0];
      double delta = inf;
      int j1 = 0;
      for (int j = 1; j <= cols; ++j) {
        if (used[j]) continue;
        const double slack = a[(i0 - 1) * cols + (j - 1)] - u[i0] - v[j];
        if (slack < min_slack[j]) min_slack[j] = slack, way[j] = j0;
        if (min_slack[j] < delta) delta = min_slack[j], j1 = j;
      }
      for (int j = 0; j <= cols; ++j) {
        if (used[j]) {
          u[row_of[j]] += delta;
          v[j] -= delta;
        } else {
          min_slack[j] -= delta;
        }
      }
      j0 = j1;
    } while (row_of[j0] != 0);
    do {
      const int j1 = way[j0];
      row_of[j0] = row_of[j1];
      j0 = j1;
    } while (j0 != 0);
  }
  std::vector<int> out(cols);
  for (int j = 1; j <= cols; ++j) out[j - 1] = row_of[j] - 1;
  return out;
}

// The matching minimising the sum of weight(d, smaller side) < 0 over its pairs, among pairs
// closer than `radius` (unpaired points cost 0), exact on each component up to `max_exact`
// points.
template <class Weight>
Matching match(std::span<const Point> estimate, const std::vector<Point>& truth,
               const TruthIndex& truth_index, std::span<const bool> observed, double radius,
               std::size_t max_exact, Weight weight) {
  const std::size_t ne = estimate.size();
  std::vector<Edge> edges;
  std::vector<std::uint32_t> near;
  for (std::size_t e = 0; e < ne; ++e) {
    truth_index.within(estimate[e].x, estimate[e].y, radius, near);
    for (std::uint32_t t : near) {
      if (!observed.empty() && !observed[t]) continue;
      const double d = std::hypot(estimate[e].x - truth[t].x, estimate[e].y - truth[t].y);
      if (d < radius) edges.push_back({static_cast<std::uint32_t>(e), t, d});
    }
  }
  Matching out;
  if (edges.empty()) return out;

  // Components, then points and edges bucketed per component (counting sort).
  const std::size_t nodes = ne + truth.size();
  DisjointSets sets(nodes);
  std::vector<char> touched(nodes, 0);
  for (const Edge& g : edges) {
    const auto t = static_cast<std::uint32_t>(ne + g.truth);
    sets.unite(g.estimate, t);
    touched[g.estimate] = touched[t] = 1;
  }
  constexpr std::uint32_t kNone = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::uint32_t> component(nodes, kNone);
  std::vector<std::uint32_t> point_count;
  for (std::uint32_t n = 0; n < nodes; ++n) {
    if (!touched[n]) continue;
    const std::uint32_t root = sets.find(n);
    if (component[root] == kNone) {
      component[root] = static_cast<std::uint32_t>(point_count.size());
      point_count.push_back(0);
    }
    component[n] = component[root];
    ++point_count[component[n]];
  }
  out.components = point_count.size();
  std::vector<std::size_t> edge_start(out.components + 1, 0);
  for (const Edge& g : edges) ++edge_start[component[g.estimate] + 1];
  std::partial_sum(edge_start.begin(), edge_start.end(), edge_start.begin());
  std::vector<Edge> by_component(edges.size());
  {
    std::vector<std::size_t> next(edge_start.begin(), edge_start.end() - 1);
    for (const Edge& g : edges) by_component[next[component[g.estimate]]++] = g;
  }
  edges.clear();
  edges.shrink_to_fit();

  // Local indices: estimates and truths numbered per component in order of first appearance.
  std::vector<std::uint32_t> local(nodes, kNone);
  std::vector<double> cost;
  for (std::size_t c = 0; c < out.components; ++c) {
    const std::span<Edge> group(by_component.data() + edge_start[c],
                                edge_start[c + 1] - edge_start[c]);
    out.largest = std::max<std::size_t>(out.largest, point_count[c]);
    int rows = 0, cols = 0;  // estimates, truths
    for (const Edge& g : group) {
      if (local[g.estimate] == kNone) local[g.estimate] = static_cast<std::uint32_t>(rows++);
      if (local[ne + g.truth] == kNone) local[ne + g.truth] = static_cast<std::uint32_t>(cols++);
    }
    const auto smaller = static_cast<std::size_t>(std::min(rows, cols));
    if (point_count[c] <= max_exact) {
      // Rows are the smaller side; every row is assigned, a zero-cost pair means "unpaired".
      const bool flip = rows > cols;
      const int r = flip ? cols : rows, k = flip ? rows : cols;
      cost.assign(static_cast<std::size_t>(r) * k, 0.0);
      for (const Edge& g : group) {
        const std::uint32_t le = local[g.estimate], lt = local[ne + g.truth];
        cost[flip ? lt * k + le : le * k + lt] = weight(g.d, smaller);
      }
      const std::vector<int> row_of = hungarian(cost, r, k);
      for (const Edge& g : group) {
        const std::uint32_t le = local[g.estimate], lt = local[ne + g.truth];
        if (flip ? row_of[le] == static_cast<int>(lt) : row_of[lt] == static_cast<int>(le)) {
          out.pairs.push_back(g);
        }
      }
    } else {
      ++out.inexact;
      std::sort(group.begin(), group.end(), [](const Edge& x, const Edge& y) { return x.d < y.d; });
      std::vector<char> used_e(rows, 0), used_t(cols, 0);
      for (const Edge& g : group) {
        char& ue = used_e[local[g.estimate]];
        char& ut = used_t[local[ne + g.truth]];
        if (ue || ut) continue;
        ue = ut = 1;
        out.pairs.push_back(g);
      }
    }
    for (const Edge& g : group) local[g.estimate] = local[ne + g.truth] = kNone;
  }
  return out;
}

void check_observed(std::span<const bool> observed, const std::vector<Point>& truth) {
  if (!observed.empty() && observed.size() != truth.size()) {
    throw std::invalid_argument("map metrics: one observed flag per true landmark");
  }
}

std::size_t counted_truth(std::span<const bool> observed, const std::vector<Point>& truth) {
  if (observed.empty()) return truth.size();
  return static_cast<std::size_t>(std::count(observed.begin(), observed.end(), true));
}

}  // namespace

Gospa gospa(std::span<const Point> estimate, const std::vector<Point>& truth,
            const TruthIndex& truth_index, std::span<const bool> observed,
            const GospaOptions& options) {
  const double c = options.cutoff, p = options.order;
  if (!std::isfinite(c) || !(c > 0) || !std::isfinite(p) || !(p >= 1)) {
    throw std::invalid_argument("gospa: the cutoff must be finite and > 0, the order >= 1");
  }
  check_observed(observed, truth);
  const double cp = std::pow(c, p);
  // Pairing at d < c saves c^p - d^p over leaving both out (alpha = 2).
  const Matching m = match(estimate, truth, truth_index, observed, c, options.max_exact_component,
                           [&](double d, std::size_t) { return std::pow(d, p) - cp; });
  Gospa g;
  for (const Edge& e : m.pairs) g.localisation += std::pow(e.d, p);
  g.assigned = m.pairs.size();
  const std::size_t nt = counted_truth(observed, truth);
  g.missed = nt - g.assigned;
  g.false_targets = estimate.size() - g.assigned;
  g.distance = std::pow(g.localisation + 0.5 * cp * static_cast<double>(g.missed + g.false_targets),
                        1.0 / p);
  const std::size_t n = std::max(estimate.size(), nt);
  if (n > 0) {
    const double sum = g.localisation + cp * static_cast<double>(n - g.assigned);
    g.ospa = std::pow(sum / static_cast<double>(n), 1.0 / p);
  }
  g.components = m.components;
  g.largest_component = m.largest;
  g.inexact_components = m.inexact;
  return g;
}

Detection precision_recall(std::span<const Point> estimate, const std::vector<Point>& truth,
                           const TruthIndex& truth_index, std::span<const bool> observed,
                           double match_radius, std::size_t max_exact_component) {
  if (!std::isfinite(match_radius) || !(match_radius > 0)) {
    throw std::invalid_argument("precision_recall: match radius must be finite and > 0");
  }
  check_observed(observed, truth);
  const double r2 = match_radius * match_radius;
  // One more pair outweighs any sum of at most `smaller` normalised squared distances (< 1).
  const Matching m = match(
      estimate, truth, truth_index, observed, match_radius, max_exact_component,
      [&](double d, std::size_t smaller) { return d * d / r2 - static_cast<double>(smaller + 1); });
  Detection out;
  out.matched = m.pairs.size();
  out.inexact_components = m.inexact;
  const std::size_t nt = counted_truth(observed, truth);
  if (!estimate.empty())
    out.precision = static_cast<double>(out.matched) / static_cast<double>(estimate.size());
  if (nt > 0) out.recall = static_cast<double>(out.matched) / static_cast<double>(nt);
  return out;
}

std::vector<Point> positions(std::span<const engine::MapLandmark> map) {
  std::vector<Point> out;
  out.reserve(map.size());
  for (const engine::MapLandmark& l : map) out.push_back({l.x, l.y});
  return out;
}

}  // namespace fastslam::tools
