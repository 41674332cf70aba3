#include "engine/internal/scan_plan.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <unordered_set>

#include "engine/angles.h"

namespace fastslam::engine::internal {

void check_control(const Control& control, double dt) {
  if (!std::isfinite(dt) || dt < 0) {
    throw std::invalid_argument("Filter::predict: dt must be finite and >= 0 (got " +
                                std::to_string(dt) + ")");
  }
  if (!std::isfinite(control.u0) || !std::isfinite(control.u1)) {
    throw std::invalid_argument("Filter::predict: control values must be finite (got " +
                                std::to_string(control.u0) + ", " + std::to_string(control.u1) +
                                ")");
  }
}

void check_time(double time, double clock, bool timed) {
  if (!std::isfinite(time)) {
    throw std::invalid_argument("Filter: time must be finite (got " + std::to_string(time) + ")");
  }
  if (timed && time < clock) {
    char text[160];
    std::snprintf(text, sizeof(text),
                  "Filter: time goes backwards: %.17g s after %.17g s (data must come in time "
                  "order)",
                  time, clock);
    throw std::invalid_argument(text);
  }
}

ScanPlan plan_scan(std::span<const Observation> scan, Association association,
                   const KnownSlots& known) {
  ScanPlan plan;
  plan.observations.reserve(scan.size());
  std::unordered_set<std::int64_t> ids_in_scan;
  auto next_slot = static_cast<memory::Slot>(known.size());
  for (std::size_t j = 0; j < scan.size(); ++j) {
    const Observation& o = scan[j];
    auto where = [j] { return "Filter::observe: observation " + std::to_string(j) + ": "; };
    if (!std::isfinite(o.range) || !(o.range > 0)) {
      throw std::invalid_argument(where() + "range must be finite and > 0 (got " +
                                  std::to_string(o.range) + ")");
    }
    if (!std::isfinite(o.bearing)) {
      throw std::invalid_argument(where() + "bearing must be finite (got " +
                                  std::to_string(o.bearing) + ")");
    }
    PlannedObservation p;
    p.z = {o.range, wrap_angle(o.bearing)};
    if (association != Association::kKnown) {
      plan.observations.push_back(p);
      continue;
    }
    if (o.id < 0) {
      throw std::invalid_argument(where() + "known association needs a landmark id >= 0 (got " +
                                  std::to_string(o.id) + ")");
    }
    if (!ids_in_scan.insert(o.id).second) {
      throw std::invalid_argument(where() + "landmark id " + std::to_string(o.id) +
                                  " appears twice in one scan");
    }
    p.id = static_cast<std::uint64_t>(o.id);
    if (auto found = known.find(o.id); found != known.end()) {
      p.slot = found->second;
    } else {
      p.slot = next_slot++;
      p.is_new = true;
      plan.new_slots.emplace(o.id, p.slot);
    }
    plan.observations.push_back(p);
  }
  if (association != Association::kKnown && scan.size() >= kLandmarkIdsPerScan) {
    throw std::invalid_argument("Filter::observe: a scan holds at most " +
                                std::to_string(kLandmarkIdsPerScan - 1) + " observations (got " +
                                std::to_string(scan.size()) + ")");
  }
  return plan;
}

MapCheck check_map(std::span<const MapLandmark> landmarks, bool known_ids, double bound) {
  MapCheck result;
  result.variance_bound = bound;
  for (std::size_t k = 0; k < landmarks.size(); ++k) {
    const MapLandmark& l = landmarks[k];
    auto where = [k] { return "Filter::set_map: landmark " + std::to_string(k) + ": "; };
    if (!std::isfinite(l.x) || !std::isfinite(l.y) || std::abs(l.x) > 1e150 ||
        std::abs(l.y) > 1e150) {
      throw std::invalid_argument(where() + "position must be finite and within 1e150");
    }
    const double det = l.sxx * l.syy - l.sxy * l.sxy;
    if (!std::isfinite(l.sxx) || !std::isfinite(l.sxy) || !std::isfinite(l.syy) || !(l.sxx > 0) ||
        !(det > 0)) {
      throw std::invalid_argument(where() + "covariance must be symmetric positive definite");
    }
    if (!std::isfinite(l.log_odds)) throw std::invalid_argument(where() + "log_odds not finite");
    if (known_ids) {
      if (l.id >= (std::uint64_t{1} << 63) ||
          !result.known.emplace(static_cast<std::int64_t>(l.id), static_cast<memory::Slot>(k))
               .second) {
        throw std::invalid_argument(where() + "id " + std::to_string(l.id) +
                                    " is repeated or too large");
      }
    }
    // The largest eigenvalue of the covariance bounds the candidate search.
    const double half_trace = 0.5 * (l.sxx + l.syy);
    result.variance_bound =
        std::max(result.variance_bound,
                 half_trace + std::sqrt(std::max(0.0, half_trace * half_trace - det)));
  }
  return result;
}

}  // namespace fastslam::engine::internal
