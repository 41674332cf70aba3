#include "tools/eval/trajectory_errors.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "engine/angles.h"

namespace fastslam::tools {

std::optional<StampedPose> pose_at(std::span<const StampedPose> samples, double t) {
  auto it = std::upper_bound(samples.begin(), samples.end(), t,
                             [](double v, const StampedPose& p) { return v < p.time; });
  if (it != samples.begin() && std::prev(it)->time == t) return *std::prev(it);
  if (it == samples.begin() || it == samples.end()) return std::nullopt;
  const StampedPose& a = *std::prev(it);
  const StampedPose& b = *it;
  if (b.time - a.time > kMaxInterpolationGap) return std::nullopt;
  const double f = (t - a.time) / (b.time - a.time);
  return StampedPose{t, a.x + f * (b.x - a.x), a.y + f * (b.y - a.y),
                     engine::wrap_angle(a.theta + f * engine::wrap_angle(b.theta - a.theta))};
}

PositionErrors position_errors(std::span<const StampedPose> estimate,
                               std::span<const StampedPose> reference) {
  PositionErrors e;
  double se = 0.0;
  for (const StampedPose& r : reference) {
    const std::optional<StampedPose> p = pose_at(estimate, r.time);
    if (!p) {
      ++e.skipped;
      continue;
    }
    const double d2 = (p->x - r.x) * (p->x - r.x) + (p->y - r.y) * (p->y - r.y);
    se += d2;
    e.last = std::sqrt(d2);
    ++e.used;
  }
  e.rmse = e.used == 0 ? 0.0 : std::sqrt(se / e.used);
  return e;
}

AlignedErrors aligned_position_errors(std::span<const StampedPose> estimate,
                                      std::span<const StampedPose> reference) {
  std::vector<std::array<double, 4>> pairs;  // estimate x, y; reference x, y
  for (const StampedPose& r : reference) {
    if (const std::optional<StampedPose> p = pose_at(estimate, r.time)) {
      pairs.push_back({p->x, p->y, r.x, r.y});
    }
  }
  AlignedErrors out;
  if (pairs.empty()) return out;
  double me[2] = {0, 0}, mr[2] = {0, 0};
  for (const auto& [ex, ey, rx, ry] : pairs) {
    me[0] += ex, me[1] += ey, mr[0] += rx, mr[1] += ry;
  }
  const auto n = static_cast<double>(pairs.size());
  for (double* m : {me, mr}) m[0] /= n, m[1] /= n;
  double cross = 0.0, dot = 0.0;
  for (const auto& [ex, ey, rx, ry] : pairs) {
    const double ax = ex - me[0], ay = ey - me[1], bx = rx - mr[0], by = ry - mr[1];
    cross += ax * by - ay * bx;
    dot += ax * bx + ay * by;
  }
  out.rotation = std::atan2(cross, dot);
  const double c = std::cos(out.rotation), sn = std::sin(out.rotation);
  double se = 0.0;
  for (const auto& [ex, ey, rx, ry] : pairs) {
    const double ax = ex - me[0], ay = ey - me[1];
    se +=
        std::pow(c * ax - sn * ay - (rx - mr[0]), 2) + std::pow(sn * ax + c * ay - (ry - mr[1]), 2);
  }
  out.rmse = std::sqrt(se / n);
  return out;
}

double landmark_rmse_by_id(std::span<const engine::MapLandmark> map,
                           std::span<const TruthLandmark> truth) {
  if (map.empty() || truth.empty()) return 0.0;
  double se = 0.0;
  std::vector<TruthLandmark> sorted(truth.begin(), truth.end());
  std::sort(sorted.begin(), sorted.end(),
            [](const TruthLandmark& a, const TruthLandmark& b) { return a.id < b.id; });
  for (const engine::MapLandmark& l : map) {
    auto it = std::lower_bound(sorted.begin(), sorted.end(), l.id,
                               [](const TruthLandmark& a, std::uint64_t id) { return a.id < id; });
    if (it == sorted.end() || it->id != l.id) {
      throw std::runtime_error("estimated landmark id " + std::to_string(l.id) +
                               " is not a true landmark");
    }
    se += (l.x - it->x) * (l.x - it->x) + (l.y - it->y) * (l.y - it->y);
  }
  return std::sqrt(se / map.size());
}

}  // namespace fastslam::tools
