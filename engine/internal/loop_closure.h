// Loop closure by matching one particle's map against itself (filter_config.h
// LoopClosureConfig), after the particle's map update in a scan that confirmed a landmark.
//
// Once resampling has left every particle with one drifted history, an old landmark seen again
// lies outside every particle's gate and is mapped a second time; the particle's recent map is
// then a shifted and turned copy of part of its old map. Recent: confirmed, associated fewer
// than min_age steps ago; old: confirmed, not associated for min_age steps. A recent landmark
// pairs with the one old landmark within `reach` (none when there are several: a pair must not be
// a guess among neighbours, which also keeps dense maps from ever pairing). Pairs taken by the
// same rigid motion keep their distances: the largest set of pairs whose distances agree within
// three standard deviations of the landmarks' own (`consistent_pairs`), if it has two pairs or
// more, gives the least-squares rigid motion of its recent landmarks onto its old ones
// (`fit_rigid_motion`), and the particle's pose and every landmark associated within min_age
// steps move by it (`move_recent`). The twins then lie together: association takes one of each
// and negative information removes the other. The particle's weight is not changed: this is a
// correction of its map, as a map join is, not a draw.
//
// The search starts from the landmarks this scan confirmed and goes on only when one of them has
// a twin, so a scan with no loop in sight costs one disc query of radius `reach` per landmark it
// confirmed. Thread safety: writes only the particle's map; concurrent calls on distinct
// particles with distinct scratch are safe. Costs: on a closure, O(N) over the particle's map
// (the recent landmarks are found by their last association, which the index does not hold) and
// the moved landmarks' path copies; the pair set is searched exhaustively over at most
// kMaxPairs pairs (2^kMaxPairs subsets, only when a closure is possible).
#pragma once

#include <algorithm>
#include <bit>
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

// The pairs searched at most (the nearest twins first): 2^kMaxPairs subsets.
inline constexpr std::size_t kMaxPairs = 10;

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
// centroids, and the angle of the cross-covariance), over the pairs whose bit is set in `mask`.
// REQUIRES: at least one bit set, pairs.size() <= 64.
inline RigidMotion fit_rigid_motion(std::span<const LoopPair> pairs, std::uint64_t mask) {
  RigidMotion m;
  double n = 0.0;
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    if (((mask >> k) & 1u) == 0) continue;
    m.from += pairs[k].a;
    m.to += pairs[k].b;
    n += 1.0;
  }
  m.from /= n;
  m.to /= n;
  double dot = 0.0;
  double cross = 0.0;
  for (std::size_t k = 0; k < pairs.size(); ++k) {
    if (((mask >> k) & 1u) == 0) continue;
    const Eigen::Vector2d a = pairs[k].a - m.from;
    const Eigen::Vector2d b = pairs[k].b - m.to;
    dot += a.dot(b);
    cross += a[0] * b[1] - a[1] * b[0];
  }
  m.turn = std::atan2(cross, dot);
  return m;
}

// The largest tolerance of the agreement test, as a share of the reach. Two unrelated pairs,
// whose offsets spread over the reach, agree within a tolerance t with a chance of about
// 0.6 t / reach: at this share about one in ten. Landmarks known only to metres (Victoria Park's
// trees under a 1 m range noise: tolerances of 3-9 m against a 10 m reach) never pair.
inline constexpr double kAgreementShare = 0.15;

// Whether pairs j and k can be taken by one rigid motion: distinct landmarks, and the distance
// between their recent landmarks within three standard deviations (from the four landmarks'
// covariance traces) of the distance between their old ones, a tolerance itself at most
// kAgreementShare of `reach`.
inline bool pairs_agree(const LoopPair& j, const LoopPair& k, double reach) {
  if (j.old == k.old || j.recent == k.recent) return false;
  const double recent = (j.a - k.a).norm();
  const double old = (j.b - k.b).norm();
  const double tolerance = 3.0 * std::sqrt(j.variance + k.variance);
  return tolerance <= kAgreementShare * reach && std::fabs(recent - old) <= tolerance;
}

// The largest set of pairs that agree two by two (pairs_agree), as a bit mask (0 when no two
// agree); among sets of one size, the one with the smallest mask. Exhaustive. REQUIRES:
// pairs.size() <= kMaxPairs.
inline std::uint64_t consistent_pairs(std::span<const LoopPair> pairs, double reach) {
  const std::size_t k = pairs.size();
  std::uint64_t agree[kMaxPairs] = {};
  for (std::size_t i = 0; i < k; ++i) {
    for (std::size_t j = 0; j < k; ++j) {
      if (i != j && pairs_agree(pairs[i], pairs[j], reach)) agree[i] |= std::uint64_t{1} << j;
    }
  }
  std::uint64_t best = 0;
  int best_size = 1;
  for (std::uint64_t mask = 1; mask < (std::uint64_t{1} << k); ++mask) {
    const int size = std::popcount(mask);
    if (size <= best_size) continue;
    bool clique = true;
    for (std::size_t i = 0; i < k && clique; ++i) {
      if (((mask >> i) & 1u) != 0) clique = (mask & ~(std::uint64_t{1} << i) & ~agree[i]) == 0;
    }
    if (clique) {
      best = mask;
      best_size = size;
    }
  }
  return best;
}

// Every landmark of `map` associated fewer than min_age steps ago moves by `motion` (mean, and
// covariance rotated). `slots` is scratch. O(N) plus the moves' path copies.
inline void move_recent(const LoopClosureInput& in, const RigidMotion& motion,
                        memory::ParticleMap& map, std::vector<memory::Slot>& slots) {
  slots.clear();
  for (const auto& e : map.tree()) {
    const std::int64_t seen = e.landmark.last_seen;
    if (seen >= 0 && in.scan_step - static_cast<std::uint64_t>(seen) < in.config.min_age) {
      slots.push_back(e.slot);
    }
  }
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

inline bool old_enough(const LoopClosureInput& in, const memory::Landmark& l) {
  return l.last_seen < 0 ||
         in.scan_step - static_cast<std::uint64_t>(l.last_seen) >= in.config.min_age;
}

// Appends (slot, its old twin) to `pairs` when exactly one old confirmed landmark lies within
// reach of the landmark in `slot`; returns whether it did.
inline bool pair_with_twin(const LoopClosureInput& in, const memory::ParticleMap& map,
                           memory::Slot slot, std::vector<LoopPair>& pairs) {
  const memory::LandmarkTree& tree = map.tree();
  const memory::Landmark& l = tree.at(slot);
  std::size_t twins = 0;
  memory::Slot twin = 0;
  map.index().within(l.x, l.y, in.config.reach, [&](const memory::SpatialEntry& e) {
    if (twins > 1 || e.slot == slot) return;  // two decide already: the pair is off
    const memory::Landmark& o = tree.at(e.slot);
    if (!old_enough(in, o) || !(o.log_odds >= in.confirm_at)) return;
    ++twins;
    twin = e.slot;
  });
  if (twins != 1) return false;
  const memory::Landmark& o = tree.at(twin);
  // And the old one has no other recent confirmed landmark within reach: twins both ways.
  std::size_t recent = 0;
  map.index().within(o.x, o.y, in.config.reach, [&](const memory::SpatialEntry& e) {
    if (recent > 1 || e.slot == twin) return;
    const memory::Landmark& r = tree.at(e.slot);
    if (old_enough(in, r) || !(r.log_odds >= in.confirm_at)) return;
    ++recent;
  });
  if (recent != 1) return false;
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
    if (loop_closure_detail::old_enough(in, l) || !(l.log_odds >= in.confirm_at)) return;
    pair_with_twin(in, map, e.slot, pairs);
  });
  if (pairs.size() < 2) return false;
  // The nearest twins first (ties by slot, so the order does not depend on the index's).
  std::sort(pairs.begin(), pairs.end(), [](const LoopPair& x, const LoopPair& y) {
    const double dx = (x.a - x.b).squaredNorm();
    const double dy = (y.a - y.b).squaredNorm();
    return dx != dy ? dx < dy : x.recent < y.recent;
  });
  if (pairs.size() > kMaxPairs) pairs.resize(kMaxPairs);
  const std::uint64_t mask = consistent_pairs(pairs, in.config.reach);
  // At least two pairs, and more than half of them: twins that disagree with the motion are
  // evidence against it.
  const auto agreeing = static_cast<std::size_t>(std::popcount(mask));
  if (agreeing < 2 || 2 * agreeing <= pairs.size()) return false;
  const RigidMotion motion = fit_rigid_motion(pairs, mask);
  move_recent(in, motion, map, scratch.moved);
  const Eigen::Vector2d at = motion.apply({pose[0], pose[1]});
  pose = Pose(at[0], at[1], wrap_angle(pose[2] + motion.turn));
  return true;
}

}  // namespace fastslam::engine::internal
