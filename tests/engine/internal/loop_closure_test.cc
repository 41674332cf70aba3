// Loop closure by matching (engine/internal/loop_closure.h) against oracles: the rigid fit
// against a direct minimisation of the squared residuals over the angle, the agreement of a set
// against every two of its pairs, and the closure on maps built as a known rigid copy of an old
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
    const RigidMotion m = fit_rigid_motion(pairs);
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

TEST(LoopClosureTest, AllPairsAgreeIsEveryTwoAgreeing) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double reach = 10.0;
  int agreeing = 0;
  for (int trial = 0; trial < 400; ++trial) {
    // Copies under one motion, and now and then a random twin within reach or a repeated old one.
    const double turn = 0.1 * u(rng);
    const Eigen::Vector2d shift(6 * u(rng), 6 * u(rng));
    std::vector<LoopPair> pairs(2 + trial % 5);
    for (std::size_t k = 0; k < pairs.size(); ++k) {
      pairs[k].recent = static_cast<memory::Slot>(k);
      pairs[k].old = static_cast<memory::Slot>(trial % 11 == 0 ? 100 : 100 + k);
      pairs[k].a = {40 * u(rng), 40 * u(rng)};
      pairs[k].variance = 0.01 + 0.04 * (1 + u(rng));
      const bool copy = (k + trial) % 4 != 0 || trial % 3 == 0;
      pairs[k].b =
          copy ? Eigen::Vector2d(rotate(pairs[k].a, turn) + shift)
               : Eigen::Vector2d(pairs[k].a + Eigen::Vector2d(reach * u(rng), reach * u(rng)));
    }
    bool every = true;
    for (std::size_t i = 0; i < pairs.size(); ++i) {
      for (std::size_t j = 0; j < pairs.size(); ++j) {
        if (i != j && !pairs_agree(pairs[i], pairs[j], reach)) every = false;
      }
    }
    EXPECT_EQ(all_pairs_agree(pairs, reach), every) << "trial " << trial;
    agreeing += every ? 1 : 0;
  }
  EXPECT_GT(agreeing, 50) << "the trials hardly exercise agreement";
  EXPECT_LT(agreeing, 350) << "the trials hardly exercise disagreement";
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

// The drift: recent = R(-turn) (old - shift); the closure must undo it.
const double kTurn = 0.05;
const Eigen::Vector2d kShift(4.0, -3.0);

Eigen::Vector2d drifted(const Eigen::Vector2d& old) { return rotate(old - kShift, -kTurn); }

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
  // Old landmarks at `olds` and a recent drifted copy of each.
  void add_twins(const std::vector<Eigen::Vector2d>& olds, double recent_log_odds = 3.0) {
    for (const auto& p : olds) old_slots.push_back(add(p, 0));
    for (const auto& p : olds) recent_slots.push_back(add(drifted(p), 4990, recent_log_odds));
  }
};

// The closure from the pose `truth` seen under a drift (its map drifted the same way) puts the
// pose back at the truth.
void expect_pose_restored(DriftedMap& w, memory::Slot confirmed, const Pose& truth,
                          Eigen::Vector2d (*drift)(const Eigen::Vector2d&), double turn) {
  const Eigen::Vector2d seen = drift({truth[0], truth[1]});
  Pose pose(seen[0], seen[1], truth[2] - turn);
  LoopClosureScratch scratch;
  ASSERT_TRUE(close_loop(w.in, std::vector<memory::Slot>{confirmed}, w.map, pose, scratch));
  EXPECT_NEAR(pose[0], truth[0], 1e-9);
  EXPECT_NEAR(pose[1], truth[1], 1e-9);
  EXPECT_NEAR(pose[2], truth[2], 1e-12);
}

TEST(LoopClosureTest, MovesADriftedCopyOntoTheOldMap) {
  DriftedMap w;
  const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}, {-5, 25}, {60, 60}};
  for (const auto& p : olds) w.old_slots.push_back(w.add(p, 0));
  for (int k = 0; k < 3; ++k) w.recent_slots.push_back(w.add(drifted(olds[k]), 4990));
  // A recent landmark with no twin within the sensor's range moves with the pose too; one seen
  // farther back on the way (beyond the range) keeps its place, since its drift is that of an
  // earlier pose.
  const memory::Slot lone = w.add({-15, -10}, 4995, 1.0);
  const memory::Landmark lone_before = w.map.tree().at(lone);
  const memory::Slot far = w.add({-40, -40}, 4995, 1.0);
  const memory::Landmark far_before = w.map.tree().at(far);
  expect_pose_restored(w, w.recent_slots[0], Pose(3.0, 2.0, 0.3), drifted, kTurn);
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
  EXPECT_EQ(w.map.tree().at(far), far_before);
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
  w.add_twins(olds);
  w.add(drifted(olds[0]) + Eigen::Vector2d(2.0, 7.0), 0);  // a second old one near a recent one
  expect_no_closure(w, {w.recent_slots[0]});
}

TEST(LoopClosureTest, TwoRecentLandmarksWithinReachOfTheOldOneMakeNoPair) {
  DriftedMap w;
  const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}};
  w.add_twins(olds);
  w.add(olds[0] + Eigen::Vector2d(-6.0, 5.0), 4990);  // another recent one near the old one
  expect_no_closure(w, {w.recent_slots[1]});
}

TEST(LoopClosureTest, AnyOtherConfirmedLandmarkWithinReachMakesNoPair) {
  DriftedMap w;
  const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}};
  w.add_twins(olds);
  // A recent confirmed landmark 7.8 m from the first recent twin and 12.8 m from its old one,
  // with no twin of its own: in a map this dense a pair could be a neighbour's.
  w.add(drifted(olds[0]) + Eigen::Vector2d(-6.0, 5.0), 4990);
  expect_no_closure(w, {w.recent_slots[1]});
  // A provisional one there does not count.
  DriftedMap v;
  v.add_twins(olds);
  v.add(drifted(olds[0]) + Eigen::Vector2d(-6.0, 5.0), 4990, 1.0);
  Pose pose(1.0, 2.0, 0.5);
  LoopClosureScratch scratch;
  EXPECT_TRUE(close_loop(v.in, std::vector<memory::Slot>{v.recent_slots[1]}, v.map, pose, scratch));
}

TEST(LoopClosureTest, ProvisionalYoungOrTwinsWithinTheirUncertaintyMakeNoPair) {
  {
    DriftedMap w;  // the recent copies are provisional
    const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}};
    w.add_twins(olds, 1.0);
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

TEST(LoopClosureTest, ATwinThatDisagreesMakesNoClosure) {
  // Three pairs agree on the drift; a fourth is a twin under another shift.
  const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}, {-20, 20}, {10, -25}};
  DriftedMap w;
  for (const auto& p : olds) w.old_slots.push_back(w.add(p, 0));
  w.recent_slots.push_back(w.add(drifted(olds[0]), 4990));
  w.recent_slots.push_back(w.add(drifted(olds[1]), 4990));
  w.recent_slots.push_back(w.add(olds[2] + Eigen::Vector2d(7, 0), 4990));
  w.recent_slots.push_back(w.add(drifted(olds[3]), 4990));
  expect_no_closure(w, {w.recent_slots[0]});
  // With the fourth one agreeing too, the loop closes.
  DriftedMap v;
  v.add_twins(olds);
  Pose pose(1.0, 2.0, 0.5);
  LoopClosureScratch scratch;
  EXPECT_TRUE(close_loop(v.in, std::vector<memory::Slot>{v.recent_slots[0]}, v.map, pose, scratch));
}

TEST(LoopClosureTest, NoSearchBeyondTheLandmarksThisScanConfirmed) {
  DriftedMap w;
  const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}};
  w.add_twins(olds);
  const memory::Slot fresh = w.add({-50, 50}, 5000);  // confirmed now, with no twin
  expect_no_closure(w, {fresh});
}

TEST(LoopClosureTest, PairRadiusIsTheSeparationBelowTheReach) {
  LoopClosureConfig c;
  c.reach = 15.0;
  c.separation = 10.0;
  EXPECT_EQ(pair_radius(c), 10.0);
  c.separation = 0.0;  // one radius
  EXPECT_EQ(pair_radius(c), 15.0);
  c.separation = 20.0;
  EXPECT_EQ(pair_radius(c), 15.0);
}

// Twins about 12 m apart: beyond a 10 m separation, within a 15 m reach.
const double kWideTurn = 0.02;
const Eigen::Vector2d kWideShift(9.0, -8.0);

Eigen::Vector2d wide_drifted(const Eigen::Vector2d& old) {
  return rotate(old - kWideShift, -kWideTurn);
}

struct WideDrift : DriftedMap {
  const std::vector<Eigen::Vector2d> olds = {{0, 0}, {45, 6}};
  WideDrift() {
    in.config.reach = 15.0;
    in.config.separation = 10.0;
    for (const auto& p : olds) old_slots.push_back(add(p, 0));
    for (const auto& p : olds) recent_slots.push_back(add(wide_drifted(p), 4990));
  }
};

TEST(LoopClosureTest, WideDriftsPairWhereTheMapIsSparse) {
  WideDrift w;
  for (std::size_t k = 0; k < 2; ++k) {
    const memory::Landmark& r = w.map.tree().at(w.recent_slots[k]);
    const double apart = (Eigen::Vector2d(r.x, r.y) - w.olds[k]).norm();
    ASSERT_GT(apart, 10.0);
    ASSERT_LT(apart, 15.0);
  }
  expect_pose_restored(w, w.recent_slots[0], Pose(20.0, 4.0, 0.1), wide_drifted, kWideTurn);
  for (std::size_t k = 0; k < 2; ++k) {
    const memory::Landmark& r = w.map.tree().at(w.recent_slots[k]);
    EXPECT_LT((Eigen::Vector2d(r.x, r.y) - w.olds[k]).norm(), 1e-9);
  }
  // With one radius of 10 m the twins are out of reach.
  WideDrift v;
  v.in.config.reach = 10.0;
  expect_no_closure(v, {v.recent_slots[0]});
}

TEST(LoopClosureTest, ANeighbourWithinTheReachStopsAWidePair) {
  WideDrift w;
  // Confirmed, 13 m from the first recent twin: beyond the separation, within the reach.
  const memory::Landmark& r = w.map.tree().at(w.recent_slots[0]);
  w.add(Eigen::Vector2d(r.x, r.y) + Eigen::Vector2d(-5.0, 12.0), 4990);
  expect_no_closure(w, {w.recent_slots[1]});
}

TEST(LoopClosureTest, TwinsWithinTheSeparationNeedBeAloneOnlyWithinIt) {
  const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}};
  // The drift's twins lie 5 m apart; a confirmed landmark 12 m from the first recent one.
  const auto build = [&](DriftedMap& w, double separation) {
    w.in.config.reach = 15.0;
    w.in.config.separation = separation;
    w.add_twins(olds);
    w.add(drifted(olds[0]) + Eigen::Vector2d(-12.0, 0.0), 4990);
  };
  DriftedMap w;
  build(w, 10.0);
  Pose pose(1.0, 2.0, 0.5);
  LoopClosureScratch scratch;
  EXPECT_TRUE(close_loop(w.in, std::vector<memory::Slot>{w.recent_slots[1]}, w.map, pose, scratch));
  DriftedMap v;  // one radius of 15 m: the neighbour makes the pair a guess
  build(v, 0.0);
  expect_no_closure(v, {v.recent_slots[1]});
}

TEST(LoopClosureTest, ATurnBeyondMaxTurnMakesNoClosure) {
  const std::vector<Eigen::Vector2d> olds = {{0, 0}, {22, 3}};
  DriftedMap w;
  w.in.config.max_turn = 0.9 * kTurn;
  w.add_twins(olds);
  expect_no_closure(w, {w.recent_slots[0]});
  DriftedMap v;
  v.in.config.max_turn = 1.1 * kTurn;
  v.add_twins(olds);
  Pose pose(1.0, 2.0, 0.5);
  LoopClosureScratch scratch;
  EXPECT_TRUE(close_loop(v.in, std::vector<memory::Slot>{v.recent_slots[0]}, v.map, pose, scratch));
}

}  // namespace
}  // namespace fastslam::engine::internal
