// Loop closure by matching one particle's map against itself (filter_config.h
// LoopClosureConfig), after the particle's map update in a scan that confirmed a landmark.
//
// Once resampling has left every particle with one drifted history, an old landmark seen again
// lies outside every particle's gate and is mapped a second time; the particle's recent map is
// then a shifted and turned copy of part of its old map. Recent: confirmed, associated fewer
// than min_age steps ago; old: confirmed, not associated for min_age steps. A recent landmark
// and an old one pair when each is the other's only confirmed neighbour within `separation`,
// or within `reach` when they lie farther apart than the separation (a pair must not be a guess
// among neighbours, which also keeps maps denser than the separation from ever pairing; the
// wider disc lets a larger drift close where the map is sparse), and they lie farther apart
// than their own uncertainty. Pairs taken by one rigid motion keep their distances: when there
// are two pairs or more and every two agree within three standard deviations of the landmarks'
// own (`pairs_agree`; a twin that disagrees is evidence that they are not all twins), the
// least-squares rigid motion of the recent landmarks onto the old ones (`fit_rigid_motion`),
// unless it turns by more than `max_turn` (two pairs agree by chance about one time in ten,
// and such a motion turns by whatever angle their chance geometry gives), moves the particle's
// pose and the landmarks within the sensor's range associated within min_age steps
// (`move_recent`): the fit holds where its pairs are, and a recent landmark farther back on the
// way carries the drift of an earlier pose, which a turn about the pairs would swing by metres.
// The twins then lie together: association takes one of each and negative information removes
// the other. The particle's weight is not changed: this is a correction of its map, as a map
// join is, not a draw.
//
// The search starts from the landmarks this scan confirmed and goes on only when one of them has
// a twin, so a scan with no loop in sight costs at most four disc queries (of the separation and
// the reach) per landmark it confirmed, each reading at most two landmarks. Thread safety: writes
// only the particle's map; concurrent calls on distinct particles with distinct scratch are safe.
// Costs: O(k^2) agreement tests for k pairs; on a closure, one disc query of the sensor's range and
// the moved landmarks' path copies.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "engine/angles.h"
#include "engine/filter_config.h"
#include "engine/internal/map_update.h"
#include "engine/pose.h"
#include "memory/landmark_tree.h"
#include "memory/particle_map.h"

namespace fastslam::engine::internal {

// What the search reads besides the particle.
struct LoopClosureInput {
  LoopClosureConfig config;
  double confirm_at = 0.0;  // ExistenceConfig::confirm_at: only confirmed landmarks pair
  double range = 0.0;       // recent landmarks are gathered within this of the pose (max range)
  std::uint64_t scan_step = 0;
};

// A recent landmark and its old twin: slots, means, and the sum of their covariances' traces.
struct LoopPair {
  memory::Slot recent = 0;
  memory::Slot old = 0;
  Eigen::Vector2d a = Eigen::Vector2d::Zero();  // the recent landmark's mean
  Eigen::Vector2d b = Eigen::Vector2d::Zero();  // the old one's
  double variance = 0.0;
};

// p -> to + R(turn) (p - from): the motion of the recent map onto the old one.
struct RigidMotion {
  Eigen::Vector2d from = Eigen::Vector2d::Zero();
  Eigen::Vector2d to = Eigen::Vector2d::Zero();
  double turn = 0.0;
  Eigen::Vector2d apply(const Eigen::Vector2d& p) const {
    const double c = std::cos(turn);
    const double s = std::sin(turn);
    const Eigen::Vector2d d = p - from;
    return to + Eigen::Vector2d(c * d[0] - s * d[1], s * d[0] + c * d[1]);
  }
};

struct LoopClosureScratch {
  std::vector<LoopPair> pairs;
  std::vector<memory::Slot> moved;
};

// The least-squares rigid motion taking the pairs' `a` onto their `b` (2-D Procrustes: the
// centroids, and the angle of the cross-covariance). REQUIRES: at least one pair.
inline RigidMotion fit_rigid_motion(std::span<const LoopPair> pairs) {
  RigidMotion m;
  for (const LoopPair& p : pairs) {
    m.from += p.a;
    m.to += p.b;
  }
  m.from /= static_cast<double>(pairs.size());
  m.to /= static_cast<double>(pairs.size());
  double dot = 0.0;
  double cross = 0.0;
  for (const LoopPair& p : pairs) {
    const Eigen::Vector2d a = p.a - m.from;
    const Eigen::Vector2d b = p.b - m.to;
    dot += a.dot(b);
    cross += a[0] * b[1] - a[1] * b[0];
  }
  m.turn = std::atan2(cross, dot);
  return m;
}

// The largest tolerance of the agreement test, as a share of the radius within which twins
// must be alone (pair_radius). Two unrelated pairs, whose offsets spread over that radius, agree
// within a tolerance t with a chance of about 0.6 t / radius: at this share about one in ten.
// Landmarks known only to metres (Victoria Park's trees under a 1 m range noise: tolerances of
// 3-9 m against a 10 m radius) never pair.
inline constexpr double kAgreementShare = 0.15;

// The radius within which twins must be each other's only confirmed neighbour when they lie
// within it: the separation, or the reach when the separation is 0 or not below it.
inline double pair_radius(const LoopClosureConfig& c) {
  return c.separation > 0.0 && c.separation < c.reach ? c.separation : c.reach;
}

// Whether pairs j and k can be taken by one rigid motion: distinct landmarks, and the distance
// between their recent landmarks within three standard deviations (from the four landmarks'
// covariance traces) of the distance between their old ones, a tolerance itself at most
// kAgreementShare of `radius` (pair_radius).
inline bool pairs_agree(const LoopPair& j, const LoopPair& k, double radius) {
  if (j.old == k.old || j.recent == k.recent) return false;
  const double recent = (j.a - k.a).norm();
  const double old = (j.b - k.b).norm();
  const double tolerance = 3.0 * std::sqrt(j.variance + k.variance);
  return tolerance <= kAgreementShare * radius && std::fabs(recent - old) <= tolerance;
}

// Whether every two of the pairs agree (pairs_agree). O(k^2).
inline bool all_pairs_agree(std::span<const LoopPair> pairs, double radius) {
  for (std::size_t i = 0; i < pairs.size(); ++i) {
    for (std::size_t j = i + 1; j < pairs.size(); ++j) {
      if (!pairs_agree(pairs[i], pairs[j], radius)) return false;
    }
  }
  return true;
}

// Whether `l` was last associated min_age steps ago or more (old), or never; else it is recent.
inline bool old_enough(const LoopClosureInput& in, const memory::Landmark& l) {
  return l.last_seen < 0 ||
         in.scan_step - static_cast<std::uint64_t>(l.last_seen) >= in.config.min_age;
}

// Every landmark of `map` within the sensor's range of `at` and associated fewer than min_age
// steps ago moves by `motion` (mean, and covariance rotated). `slots` is scratch. One disc query
// plus the moves' path copies.
inline void move_recent(const LoopClosureInput& in, const RigidMotion& motion,
                        const Eigen::Vector2d& at, memory::ParticleMap& map,
                        std::vector<memory::Slot>& slots) {
  slots.clear();
  const memory::LandmarkTree& tree = map.tree();
  map.index().within(at[0], at[1], in.range, [&](const memory::SpatialEntry& e) {
    if (!old_enough(in, tree.at(e.slot))) slots.push_back(e.slot);
  });
  std::sort(slots.begin(), slots.end());
  const double c = std::cos(motion.turn);
  const double s = std::sin(motion.turn);
  map.update_each(
      slots,
      [&](std::size_t, memory::Landmark& l) {
        const Eigen::Vector2d p = motion.apply({l.x, l.y});
        l.x = p[0];
        l.y = p[1];
        const double xx = l.sxx;
        const double xy = l.sxy;
        const double yy = l.syy;
        l.sxx = c * c * xx - 2.0 * c * s * xy + s * s * yy;
        l.syy = s * s * xx + 2.0 * c * s * xy + c * c * yy;
        l.sxy = c * s * (xx - yy) + (c * c - s * s) * xy;
      },
      largest_variance);
}

namespace loop_closure_detail {

// Appends (slot, its old twin) to `pairs` when the landmark in `slot` and an old confirmed one
// are each other's only confirmed neighbour within pair_radius, or, with none within it, within
// the reach; returns whether it did.
inline bool pair_with_twin(const LoopClosureInput& in, const memory::ParticleMap& map,
                           memory::Slot slot, std::vector<LoopPair>& pairs) {
  const memory::LandmarkTree& tree = map.tree();
  // How many confirmed landmarks other than `self` lie within `radius` of `at`, counting to two
  // (then it stops reading landmarks); `found` is the last one counted.
  const auto neighbours = [&](const memory::Landmark& at, memory::Slot self, double radius,
                              memory::Slot& found) {
    std::size_t n = 0;
    map.index().within(at.x, at.y, radius, [&](const memory::SpatialEntry& e) {
      if (n > 1 || e.slot == self) return;
      if (!(tree.at(e.slot).log_odds >= in.confirm_at)) return;
      ++n;
      found = e.slot;
    });
    return n;
  };
  const memory::Landmark& l = tree.at(slot);
  memory::Slot twin = 0;
  double radius = pair_radius(in.config);
  std::size_t n = neighbours(l, slot, radius, twin);
  if (n == 0 && radius < in.config.reach) {
    radius = in.config.reach;
    n = neighbours(l, slot, radius, twin);
  }
  if (n != 1) return false;
  const memory::Landmark& o = tree.at(twin);
  memory::Slot back = 0;
  if (!old_enough(in, o) || neighbours(o, twin, radius, back) != 1 || back != slot) return false;
  // Twins within their own uncertainty of each other are one landmark mapped twice, not a drift.
  const double variance = l.sxx + l.syy + o.sxx + o.syy;
  if ((Eigen::Vector2d(l.x, l.y) - Eigen::Vector2d(o.x, o.y)).squaredNorm() <= 9.0 * variance) {
    return false;
  }
  pairs.push_back({slot, twin, {l.x, l.y}, {o.x, o.y}, variance});
  return true;
}

}  // namespace loop_closure_detail

// The closure for one particle at `pose` after a scan that confirmed the landmarks in
// `confirmed`. On a closure moves the particle's recent landmarks, sets `pose` to the moved pose
// and returns true; otherwise changes nothing and returns false.
inline bool close_loop(const LoopClosureInput& in, std::span<const memory::Slot> confirmed,
                       memory::ParticleMap& map, Pose& pose, LoopClosureScratch& scratch) {
  using loop_closure_detail::pair_with_twin;
  std::vector<LoopPair>& pairs = scratch.pairs;
  pairs.clear();
  for (const memory::Slot slot : confirmed) pair_with_twin(in, map, slot, pairs);
  if (pairs.empty()) return false;
  const memory::LandmarkTree& tree = map.tree();
  map.index().within(pose[0], pose[1], in.range, [&](const memory::SpatialEntry& e) {
    if (std::find(confirmed.begin(), confirmed.end(), e.slot) != confirmed.end()) return;
    const memory::Landmark& l = tree.at(e.slot);
    if (old_enough(in, l) || !(l.log_odds >= in.confirm_at)) return;
    pair_with_twin(in, map, e.slot, pairs);
  });
  if (pairs.size() < 2 || !all_pairs_agree(pairs, pair_radius(in.config))) return false;
  // In slot order, so that the fit's sums do not depend on the index's layout (a loaded state
  // rebuilds it).
  std::sort(pairs.begin(), pairs.end(),
            [](const LoopPair& x, const LoopPair& y) { return x.recent < y.recent; });
  const RigidMotion motion = fit_rigid_motion(pairs);
  if (!(std::fabs(motion.turn) <= in.config.max_turn)) return false;
  move_recent(in, motion, {pose[0], pose[1]}, map, scratch.moved);
  const Eigen::Vector2d at = motion.apply({pose[0], pose[1]});
  pose = Pose(at[0], at[1], wrap_angle(pose[2] + motion.turn));
  return true;
}

}  // namespace fastslam::engine::internal
