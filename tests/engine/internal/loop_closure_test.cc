// Loop closure by matching (engine/internal/loop_closure.h) against oracles: the rigid fit
// against a direct minimisation of the squared residuals over the angle, the pair set against an
// enumeration of subsets by size, and the closure on maps built as a known rigid copy of an old
// map, where the moved pose, means and covariances are known in closed form.
#include "engine/internal/loop_closure.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "memory/node_heap.h"

namespace fastslam::engine::internal {
namespace {

Eigen::Vector2d rotate(const Eigen::Vector2d& p, double angle) {
  return {std::cos(angle) * p[0] - std::sin(angle) * p[1],
          std::sin(angle) * p[0] + std::cos(angle) * p[1]};
}

double squared_residual(std::span<const LoopPair> pairs, double angle, const Eigen::Vector2d& ca,
                        const Eigen::Vector2d& cb) {
  double sum = 0.0;
  for (const LoopPair& p : pairs) sum += (cb + rotate(p.a - ca, angle) - p.b).squaredNorm();
  return sum;
}

TEST(LoopClosureTest, RigidFitMinimisesTheSquaredResiduals) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 200; ++trial) {
    const double turn = std::numbers::pi * u(rng);
    const Eigen::Vector2d shift(10 * u(rng), 10 * u(rng));
    std::vector<LoopPair> pairs(2 + trial % 5);
    for (std::size_t k = 0; k < pairs.size(); ++k) {
      pairs[k].a = {30 * u(rng), 30 * u(rng)};
      const double noise = trial % 2 == 0 ? 0.0 : 0.3;
      pairs[k].b =
          rotate(pairs[k].a, turn) + shift + Eigen::Vector2d(noise * u(rng), noise * u(rng));
    }
    const std::uint64_t all = (std::uint64_t{1} << pairs.size()) - 1;
    const RigidMotion m = fit_rigid_motion(pairs, all);
    // The optimal translation maps centroid onto centroid; the angle is then a 1-D problem:
    // a fine grid and a golden-section refinement find its minimum independently.
    Eigen::Vector2d ca = Eigen::Vector2d::Zero(), cb = Eigen::Vector2d::Zero();
    for (const LoopPair& p : pairs) {
      ca += p.a / static_cast<double>(pairs.size());
      cb += p.b / static_cast<double>(pairs.size());
    }
    double best = 0.0;
    for (int g = 0; g < 3600; ++g) {
      const double angle = -std::numbers::pi + 2 * std::numbers::pi * g / 3600;
      if (squared_residual(pairs, angle, ca, cb) < squared_residual(pairs, best, ca, cb)) {
        best = angle;
      }
    }
    double lo = best - 0.002, hi = best + 0.002;
    for (int it = 0; it < 100; ++it) {
      const double m1 = lo + (hi - lo) * 0.382, m2 = lo + (hi - lo) * 0.618;
      (squared_residual(pairs, m1, ca, cb) < squared_residual(pairs, m2, ca, cb) ? hi : lo) =
          (squared_residual(pairs, m1, ca, cb) < squared_residual(pairs, m2, ca, cb) ? m2 : m1);
    }
    EXPECT_NEAR(std::remainder(m.turn - 0.5 * (lo + hi), 2 * std::numbers::pi), 0.0, 1e-6);
    EXPECT_LT((m.from - ca).norm(), 1e-9);
    EXPECT_LT((m.to - cb).norm(), 1e-9);
    if (trial % 2 == 0) {  // exact copies: the motion itself comes back
      EXPECT_NEAR(std::remainder(m.turn - turn, 2 * std::numbers::pi), 0.0, 1e-9);
      for (const LoopPair& p : pairs) EXPECT_LT((m.apply(p.a) - p.b).norm(), 1e-9);
    }
  }
}

TEST(LoopClosureTest, RigidFitUsesOnlyTheMaskedPairs) {
  std::vector<LoopPair> pairs(3);
  pairs[0].a = {0, 0};
  pairs[0].b = {1, 0};
  pairs[1].a = {10, 0};
  pairs[1].b = {11, 0};
  pairs[2].a = {5, 5};
  pairs[2].b = {-40, 7};  // an outlier left out by the mask
  const RigidMotion m = fit_rigid_motion(pairs, 0b011);
  EXPECT_NEAR(m.turn, 0.0, 1e-12);
  EXPECT_LT((m.apply({5, 5}) - Eigen::Vector2d(6, 5)).norm(), 1e-12);
}

// The largest set of pairwise-agreeing pairs, by an enumeration of subsets from the largest size
// down (std::prev_permutation over a selector), the first found in that order.
std::size_t largest_agreeing_size(std::span<const LoopPair> pairs, double reach) {
  for (std::size_t size = pairs.size(); size >= 2; --size) {
    std::vector<bool> pick(pairs.size(), false);
    std::fill(pick.begin(), pick.begin() + static_cast<std::ptrdiff_t>(size), true);
    do {
      bool ok = true;
      for (std::size_t i = 0; i < pairs.size() && ok; ++i) {
        for (std::size_t j = i + 1; j < pairs.size() && ok; ++j) {
          if (pick[i] && pick[j]) ok = pairs_agree(pairs[i], pairs[j], reach);
        }
      }
      if (ok) return size;
    } while (std::prev_permutation(pick.begin(), pick.end()));
  }
  return 0;
}

TEST(LoopClosureTest, ConsistentPairsIsALargestAgreeingSet) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double reach = 10.0;
  int closures = 0;
  for (int trial = 0; trial < 400; ++trial) {
    // Some pairs are copies under one motion, the rest random twins within reach.
    const double turn = 0.1 * u(rng);
    const Eigen::Vector2d shift(6 * u(rng), 6 * u(rng));
    std::vector<LoopPair> pairs(1 + trial % kMaxPairs);
    for (std::size_t k = 0; k < pairs.size(); ++k) {
      pairs[k].recent = static_cast<memory::Slot>(k);
      pairs[k].old = static_cast<memory::Slot>(100 + k % (3 + trial % 7));  // some old repeat
      pairs[k].a = {40 * u(rng), 40 * u(rng)};
      pairs[k].variance = 0.02 + 0.1 * (1 + u(rng));
      pairs[k].b =
          (k + trial) % 3 != 0
              ? Eigen::Vector2d(rotate(pairs[k].a, turn) + shift)
              : Eigen::Vector2d(pairs[k].a + Eigen::Vector2d(reach * u(rng), reach * u(rng)));
    }
    const std::uint64_t mask = consistent_pairs(pairs, reach);
    const auto size = static_cast<std::size_t>(std::popcount(mask));
    EXPECT_EQ(size, largest_agreeing_size(pairs, reach)) << "trial " << trial;
    for (std::size_t i = 0; i < pairs.size(); ++i) {
      for (std::size_t j = 0; j < pairs.size(); ++j) {
        if (i != j && ((mask >> i) & (mask >> j) & 1u) != 0) {
          EXPECT_TRUE(pairs_agree(pairs[i], pairs[j], reach));
        }
      }
    }
    closures += size >= 2 ? 1 : 0;
  }
  EXPECT_GT(closures, 100) << "the trials hardly exercise a set";
}

TEST(LoopClosureTest, AgreementNeedsTwinsPreciseAgainstTheReach) {
  LoopPair j, k;
  j.recent = 1;
  j.old = 2;
  k.recent = 3;
  k.old = 4;
  j.a = {0, 0};
  j.b = {5, 0};
  k.a = {20, 0};
  k.b = {25, 0};  // the same shift: distances agree exactly
  j.variance = k.variance = 0.01;
  EXPECT_TRUE(pairs_agree(j, k, 10.0));
  // Tolerance 3 sqrt(2 v) above kAgreementShare * reach: uninformative, refused.
  j.variance = k.variance = std::pow(kAgreementShare * 10.0 / 3.0, 2) / 2.0 * 1.01;
  EXPECT_FALSE(pairs_agree(j, k, 10.0));
  j.variance = k.variance = 0.01;
  k.b = {27, 0};  // distances 20 and 22: outside 3 sqrt(0.02)
  EXPECT_FALSE(pairs_agree(j, k, 10.0));
  k.b = {25, 0};
  k.old = 2;  // one old landmark cannot be the twin of two
  EXPECT_FALSE(pairs_agree(j, k, 10.0));
}

// A particle's map: old landmarks at `olds` (last seen at step 0), and a recent copy of some of
// them moved by the inverse of `drift` (seen at `now`), all confirmed.
struct DriftedMap {
  memory::PoolHeap heap;
  memory::ParticleMap map{heap, memory::Indexing::kSpatial};
  LoopClosureInput in;
  std::vector<memory::Slot> old_slots, recent_slots;

  DriftedMap() {
    in.config.reach = 10.0;
    in.config.min_age = 1000;
    in.confirm_at = 2.0;
    in.range = 30.0;
    in.scan_step = 5000;
  }
  memory::Slot add(const Eigen::Vector2d& p, std::int64_t last_seen, double log_odds = 3.0,
                   double var = 0.01) {
    memory::Landmark l{p[0], p[1], var, 0.3 * var, 2 * var, log_odds, 0, last_seen};
    return map.insert(l, largest_variance(l));
  }
};

// The drift: recent = R(-turn) (old - shift); the closure must undo it.
const double kTurn = 0.05;
const Eigen::Vector2d kShift(4.0, -3.0);

Eigen::Vector2d drifted(const Eigen::Vector2d& old) { return rotate(old - kShift, -kTurn); }

TEST(LoopClosureTest, MovesADriftedCopyOntoTheOldMap) {
  DriftedMap w;
  const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}, {-5, 25}, {60, 60}};
  for (const auto& p : olds) w.old_slots.push_back(w.add(p, 0));
  for (int k = 0; k < 3; ++k) w.recent_slots.push_back(w.add(drifted(olds[k]), 4990));
  // A recent landmark with no twin (seen on the way) moves with the pose too.
  const memory::Slot lone = w.add({-40, -40}, 4995, 1.0);
  const memory::Landmark lone_before = w.map.tree().at(lone);
  const Pose truth(3.0, 2.0, 0.3);
  const Eigen::Vector2d seen = drifted({truth[0], truth[1]});
  Pose pose(seen[0], seen[1], truth[2] - kTurn);
  LoopClosureScratch scratch;
  ASSERT_TRUE(close_loop(w.in, std::vector<memory::Slot>{w.recent_slots[0]}, w.map, pose, scratch));
  EXPECT_NEAR(pose[0], truth[0], 1e-9);
  EXPECT_NEAR(pose[1], truth[1], 1e-9);
  EXPECT_NEAR(pose[2], truth[2], 1e-12);
  for (int k = 0; k < 3; ++k) {
    const memory::Landmark& r = w.map.tree().at(w.recent_slots[k]);
    EXPECT_LT((Eigen::Vector2d(r.x, r.y) - olds[k]).norm(), 1e-9);
    // Covariance rotated by the turn: R S R^T.
    Eigen::Matrix2d s;
    s << 0.01, 0.003, 0.003, 0.02;
    Eigen::Matrix2d rot;
    rot << std::cos(kTurn), -std::sin(kTurn), std::sin(kTurn), std::cos(kTurn);
    const Eigen::Matrix2d want = rot * s * rot.transpose();
    EXPECT_NEAR(r.sxx, want(0, 0), 1e-15);
    EXPECT_NEAR(r.sxy, want(0, 1), 1e-15);
    EXPECT_NEAR(r.syy, want(1, 1), 1e-15);
  }
  for (std::size_t k = 0; k < olds.size(); ++k) {
    const memory::Landmark& o = w.map.tree().at(w.old_slots[k]);
    EXPECT_EQ(o.x, olds[k][0]);
    EXPECT_EQ(o.y, olds[k][1]);
  }
  const memory::Landmark& moved = w.map.tree().at(lone);
  const Eigen::Vector2d want =
      rotate(Eigen::Vector2d(lone_before.x, lone_before.y), kTurn) + kShift;
  EXPECT_LT((Eigen::Vector2d(moved.x, moved.y) - want).norm(), 1e-9);
  EXPECT_EQ(moved.log_odds, lone_before.log_odds);
  // The index moved with the means: a disc at each old landmark finds its twin now.
  for (int k = 0; k < 3; ++k) {
    std::vector<memory::Slot> near;
    w.map.index().within(olds[k][0], olds[k][1], 1e-6,
                         [&](const memory::SpatialEntry& e) { near.push_back(e.slot); });
    std::sort(near.begin(), near.end());
    EXPECT_EQ(near, (std::vector<memory::Slot>{std::min(w.old_slots[k], w.recent_slots[k]),
                                               std::max(w.old_slots[k], w.recent_slots[k])}));
  }
}

// Each refusal leaves the map and the pose exactly as they were.
void expect_no_closure(DriftedMap& w, const std::vector<memory::Slot>& confirmed) {
  std::vector<memory::Landmark> before;
  for (const auto& e : w.map.tree()) before.push_back(e.landmark);
  Pose pose(1.0, 2.0, 0.5);
  LoopClosureScratch scratch;
  EXPECT_FALSE(close_loop(w.in, confirmed, w.map, pose, scratch));
  EXPECT_EQ(pose, Pose(1.0, 2.0, 0.5));
  std::vector<memory::Landmark> after;
  for (const auto& e : w.map.tree()) after.push_back(e.landmark);
  EXPECT_EQ(before, after);
}

TEST(LoopClosureTest, OneAgreeingPairIsNotEnough) {
  DriftedMap w;
  w.old_slots.push_back(w.add({0, 0}, 0));
  w.recent_slots.push_back(w.add(drifted({0, 0}), 4990));
  expect_no_closure(w, w.recent_slots);
}

TEST(LoopClosureTest, TwoOldLandmarksWithinReachMakeNoPair) {
  DriftedMap w;
  const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}};
  for (const auto& p : olds) w.old_slots.push_back(w.add(p, 0));
  for (const auto& p : olds) w.recent_slots.push_back(w.add(drifted(p), 4990));
  w.add(drifted(olds[0]) + Eigen::Vector2d(2.0, 7.0), 0);  // a second old one near a recent one
  expect_no_closure(w, {w.recent_slots[0]});
}

TEST(LoopClosureTest, TwoRecentLandmarksWithinReachOfTheOldOneMakeNoPair) {
  DriftedMap w;
  const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}};
  for (const auto& p : olds) w.old_slots.push_back(w.add(p, 0));
  for (const auto& p : olds) w.recent_slots.push_back(w.add(drifted(p), 4990));
  w.add(olds[0] + Eigen::Vector2d(-6.0, 5.0), 4990);  // another recent one near the old one
  expect_no_closure(w, {w.recent_slots[1]});
}

TEST(LoopClosureTest, ProvisionalYoungOrTwinsWithinTheirUncertaintyMakeNoPair) {
  {
    DriftedMap w;  // the recent copies are provisional
    const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}};
    for (const auto& p : olds) w.old_slots.push_back(w.add(p, 0));
    for (const auto& p : olds) w.recent_slots.push_back(w.add(drifted(p), 4990, 1.0));
    expect_no_closure(w, w.recent_slots);
  }
  {
    DriftedMap w;  // the "old" landmarks were seen within min_age
    const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}};
    for (const auto& p : olds) w.old_slots.push_back(w.add(p, 4100));
    for (const auto& p : olds) w.recent_slots.push_back(w.add(drifted(p), 4990));
    expect_no_closure(w, w.recent_slots);
  }
  {
    DriftedMap w;  // each landmark mapped twice where it is: no drift to correct
    const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}};
    for (const auto& p : olds) w.old_slots.push_back(w.add(p, 0));
    for (const auto& p : olds) w.recent_slots.push_back(w.add(p + Eigen::Vector2d(0.3, 0), 4990));
    expect_no_closure(w, w.recent_slots);
  }
}

TEST(LoopClosureTest, TwinsThatMostlyDisagreeMakeNoClosure) {
  DriftedMap w;
  // Two pairs agree on the drift, two more are twins under other shifts (and disagree with both).
  const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}, {-20, 20}, {10, -25}};
  for (const auto& p : olds) w.old_slots.push_back(w.add(p, 0));
  w.recent_slots.push_back(w.add(drifted(olds[0]), 4990));
  w.recent_slots.push_back(w.add(drifted(olds[1]), 4990));
  w.recent_slots.push_back(w.add(olds[2] + Eigen::Vector2d(7, 0), 4990));
  w.recent_slots.push_back(w.add(olds[3] + Eigen::Vector2d(0, 8), 4990));
  expect_no_closure(w, {w.recent_slots[0]});
  // With the fourth one agreeing, three of four do: the loop closes.
  DriftedMap v;
  for (const auto& p : olds) v.old_slots.push_back(v.add(p, 0));
  v.recent_slots.push_back(v.add(drifted(olds[0]), 4990));
  v.recent_slots.push_back(v.add(drifted(olds[1]), 4990));
  v.recent_slots.push_back(v.add(olds[2] + Eigen::Vector2d(7, 0), 4990));
  v.recent_slots.push_back(v.add(drifted(olds[3]), 4990));
  Pose pose(1.0, 2.0, 0.5);
  LoopClosureScratch scratch;
  EXPECT_TRUE(close_loop(v.in, std::vector<memory::Slot>{v.recent_slots[0]}, v.map, pose, scratch));
}

TEST(LoopClosureTest, NoSearchBeyondTheLandmarksThisScanConfirmed) {
  DriftedMap w;
  const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}};
  for (const auto& p : olds) w.old_slots.push_back(w.add(p, 0));
  for (const auto& p : olds) w.recent_slots.push_back(w.add(drifted(p), 4990));
  const memory::Slot fresh = w.add({-50, 50}, 5000);  // confirmed now, with no twin
  expect_no_closure(w, {fresh});
}

}  // namespace
}  // namespace fastslam::engine::internal
