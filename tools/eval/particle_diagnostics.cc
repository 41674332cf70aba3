#include "tools/eval/particle_diagnostics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>
#include <vector>

namespace fastslam::tools {

ParticleDiagnostics diagnose_particles(std::span<const double> x, std::span<const double> y,
                                       std::span<const double> log_weight,
                                       const std::optional<StampedPose>& truth) {
  const std::size_t m = x.size();
  if (m == 0 || y.size() != m || log_weight.size() != m) {
    throw std::invalid_argument("diagnose_particles: x, y and log_weight must be one size > 0");
  }
  const double top = *std::max_element(log_weight.begin(), log_weight.end());
  if (!std::isfinite(top)) {
    throw std::invalid_argument("diagnose_particles: no particle has a finite log-weight");
  }
  std::vector<double> w(m);
  double sum = 0.0;
  for (std::size_t i = 0; i < m; ++i) sum += w[i] = std::exp(log_weight[i] - top);
  double w2 = 0.0, mx = 0.0, my = 0.0;
  for (std::size_t i = 0; i < m; ++i) {
    w[i] /= sum;
    w2 += w[i] * w[i];
    mx += w[i] * x[i];
    my += w[i] * y[i];
  }
  ParticleDiagnostics d;
  d.effective_sample_size = 1.0 / w2;
  double var = 0.0;
  for (std::size_t i = 0; i < m; ++i) {
    var += w[i] * ((x[i] - mx) * (x[i] - mx) + (y[i] - my) * (y[i] - my));
  }
  d.spread = std::sqrt(var);
  std::vector<std::pair<double, double>> positions(m);
  for (std::size_t i = 0; i < m; ++i) positions[i] = {x[i], y[i]};
  std::sort(positions.begin(), positions.end());
  d.distinct =
      static_cast<std::size_t>(std::unique(positions.begin(), positions.end()) - positions.begin());
  if (truth) {
    if (d.spread > 0) d.truth_spreads = std::hypot(truth->x - mx, truth->y - my) / d.spread;
    std::size_t nearest = 0;
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < m; ++i) {
      const double d2 =
          (x[i] - truth->x) * (x[i] - truth->x) + (y[i] - truth->y) * (y[i] - truth->y);
      if (d2 < best) {
        best = d2;
        nearest = i;
      }
    }
    d.nearest_weight = w[nearest] * static_cast<double>(m);
  }
  return d;
}

}  // namespace fastslam::tools
