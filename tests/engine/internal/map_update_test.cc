// The unknown-id map update against an oracle: a std::map copy of the landmarks changed by the
// scalar EKF (engine/landmark_ekf.h), negative information decided by brute-force geometry over
// every landmark, new landmarks by initialize_landmark; afterwards the spatial index must hold
// exactly the map's slots, means and extents. FastSLAM 1.0's reuse of the association's terms
// must give the same bits as 2.0's evaluation at the same pose.
#include "engine/internal/map_update.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <random>
#include <vector>

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

#include "engine/angles.h"
#include "engine/association.h"
#include "memory/node_heap.h"

namespace fastslam::engine::internal {
namespace {

TEST(MapUpdateTest, LargestVarianceIsTheEigenvalueRoundedUp) {
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < 1000; ++k) {
    Eigen::Matrix2d a;
    a << u(rng), u(rng), u(rng), u(rng);
    const Eigen::Matrix2d cov = a * a.transpose() * std::pow(10.0, 3 * u(rng));
    const memory::Landmark l{0, 0, cov(0, 0), cov(0, 1), cov(1, 1), 0, 0, 0};
    const double exact = Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(cov).eigenvalues()[1];
    const float got = largest_variance(l);
    EXPECT_GE(static_cast<double>(got), exact * (1 - 1e-14));
    EXPECT_LE(static_cast<double>(got), exact * (1 + 2e-7) + 1e-300);
  }
}

struct World {
  memory::PoolHeap heap;
  memory::ParticleMap map{heap, memory::Indexing::kSpatial};
  std::map<memory::Slot, memory::Landmark> oracle;
  RangeBearingModel sensor{SensorOffset{0.3, 0.0, 0.1}};
  MapUpdateInput in;
  Pose pose{2.0, 1.0, 0.4};
  std::vector<PlannedObservation> scan;
  std::vector<std::int64_t> assignment;

  World() {
    std::mt19937_64 rng(5);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    in.sensor = &sensor;
    in.r << 0.01, 0, 0, 0.0004;
    in.existence.initial = 0.7;
    in.existence.seen = 0.5;
    in.existence.missed = 0.6;
    in.existence.remove_below = 0.0;
    in.existence.confirm_at = 1.5;  // within reach of the log-odds below: some are confirmed
    in.existence.range_margin = 1.0;
    in.max_range = 15.0;
    in.field_of_view = 2.0;
    in.scan_step = 33;
    for (int k = 0; k < 300; ++k) {
      // log-odds 0.2..1.8: a miss removes some, keeps others.
      const memory::Landmark l{20 * u(rng),
                               20 * u(rng),
                               0.05,
                               0.0,
                               0.05,
                               1.0 + 0.8 * u(rng),
                               static_cast<std::uint64_t>(k),
                               4};
      oracle[map.insert(l, largest_variance(l))] = l;
    }
    // Observations: every 7th landmark in view is observed (slightly off), plus three new ones.
    int seen = 0;
    for (const auto& [slot, l] : oracle) {
      if (!in_view(l) || seen++ % 7 != 0) continue;
      PlannedObservation o;
      o.z = sensor.predict({l.x + 0.05, l.y - 0.03}, pose);
      scan.push_back(o);
      assignment.push_back(slot);
    }
    for (int k = 0; k < 3; ++k) {
      PlannedObservation o;
      o.z = {4.0 + k, 0.2 * k - 0.2};
      scan.push_back(o);
      assignment.push_back(kNewLandmark);
    }
  }

  bool in_view(const memory::Landmark& l) const {
    const Eigen::Vector2d at = sensor.sensor_position(pose);
    const double dx = l.x - at[0], dy = l.y - at[1];
    const double bearing = std::remainder(std::atan2(dy, dx) - (pose[2] + 0.1), 2 * kPi);
    return std::hypot(dx, dy) <= in.max_range - in.existence.range_margin &&
           std::fabs(bearing) <= in.field_of_view / 2;
  }
};

void expect_index_is_the_map(const memory::ParticleMap& map) {
  const memory::SpatialIndex& index = map.index();
  std::map<memory::Slot, memory::SpatialEntry> entries;
  index.within(0.0, 0.0, 1e6, [&](const memory::SpatialEntry& e) { entries[e.slot] = e; });
  ASSERT_EQ(entries.size(), map.size());
  for (const auto [slot, l] : map) {
    ASSERT_TRUE(entries.count(slot)) << slot;
    EXPECT_EQ(entries[slot].x, l.x);
    EXPECT_EQ(entries[slot].y, l.y);
    EXPECT_EQ(entries[slot].extent, largest_variance(l));
  }
}

TEST(MapUpdateTest, MatchesTheOracle) {
  World w;
  MapUpdateScratch scratch;
  MapUpdateCounts counts;
  update_particle_map<true>(w.in, w.pose, w.scan, w.assignment, {}, {}, w.map, scratch, counts);
  std::map<memory::Slot, memory::Landmark> want = w.oracle;
  std::uint64_t removed = 0;
  std::vector<memory::Slot> confirmed;  // chosen, and their log-odds reached confirm_at
  for (auto it = want.begin(); it != want.end();) {
    memory::Landmark& l = it->second;
    const auto chosen = std::find(w.assignment.begin(), w.assignment.end(), it->first);
    if (chosen != w.assignment.end()) {
      LandmarkGaussian g = to_gaussian(l);
      update_landmark(w.sensor, g, w.pose, w.scan[chosen - w.assignment.begin()].z, w.in.r);
      store_gaussian(g, l);
      if (l.log_odds < w.in.existence.confirm_at && l.log_odds + 0.5 >= w.in.existence.confirm_at) {
        confirmed.push_back(it->first);
      }
      l.log_odds += 0.5;
      l.last_seen = 33;
    } else if (w.in_view(l)) {
      l.log_odds -= 0.6;
      if (l.log_odds < 0.0) {
        it = want.erase(it);
        ++removed;
        continue;
      }
    }
    ++it;
  }
  EXPECT_GT(removed, 0u);
  EXPECT_EQ(counts.removed, removed);
  ASSERT_GT(confirmed.size(), 0u);
  std::vector<memory::Slot> got = scratch.confirmed;
  std::sort(got.begin(), got.end());
  EXPECT_EQ(got, confirmed);
  EXPECT_EQ(counts.created, 3u);
  std::size_t new_seen = 0;
  for (const auto [slot, l] : w.map) {
    const auto found = want.find(slot);
    if (found == want.end()) {
      // A new landmark: id (scan step) * 2^20 + observation index.
      const std::size_t j = l.id - 33 * kLandmarkIdsPerScan;
      ASSERT_LT(j, w.scan.size());
      EXPECT_EQ(w.assignment[j], kNewLandmark);
      const LandmarkGaussian g = initialize_landmark(w.sensor, w.pose, w.scan[j].z, w.in.r);
      EXPECT_EQ(l.x, g.mean[0]);
      EXPECT_EQ(l.log_odds, 0.7);
      ++new_seen;
      continue;
    }
    EXPECT_NEAR(l.x, found->second.x, 1e-12);
    EXPECT_NEAR(l.y, found->second.y, 1e-12);
    EXPECT_NEAR(l.sxx, found->second.sxx, 1e-12);
    EXPECT_DOUBLE_EQ(l.log_odds, found->second.log_odds);
    EXPECT_EQ(l.last_seen, found->second.last_seen);
  }
  EXPECT_EQ(new_seen, 3u);
  EXPECT_EQ(w.map.size(), want.size() + 3);
  expect_index_is_the_map(w.map);
}

// New landmarks that start at or above confirm_at are confirmed by their scan too.
TEST(MapUpdateTest, NewLandmarksStartingConfirmedAreListed) {
  World w;
  w.in.existence.confirm_at = 0.7;  // the initial log-odds
  MapUpdateScratch scratch;
  MapUpdateCounts counts;
  update_particle_map<true>(w.in, w.pose, w.scan, w.assignment, {}, {}, w.map, scratch, counts);
  std::vector<memory::Slot> fresh;  // the three new landmarks, by their ids
  for (const auto [slot, l] : w.map) {
    if (l.id >= 33 * kLandmarkIdsPerScan) fresh.push_back(slot);
  }
  ASSERT_EQ(fresh.size(), 3u);
  for (const memory::Slot slot : fresh) {
    EXPECT_NE(std::find(scratch.confirmed.begin(), scratch.confirmed.end(), slot),
              scratch.confirmed.end())
        << slot;
  }
  // Each chosen landmark listed crossed 0.7 in this scan.
  for (const memory::Slot slot : scratch.confirmed) {
    if (std::find(fresh.begin(), fresh.end(), slot) != fresh.end()) continue;
    EXPECT_LT(w.oracle.at(slot).log_odds, 0.7);
    EXPECT_GE(w.oracle.at(slot).log_odds + 0.5, 0.7);
  }
}

TEST(MapUpdateTest, ReusedTermsGiveTheSameBits) {
  World a, b;
  std::vector<LandmarkObservation> terms;
  std::vector<std::uint32_t> chosen_terms(a.scan.size(), 0);
  for (std::size_t j = 0; j < a.scan.size(); ++j) {
    if (a.assignment[j] == kNewLandmark) continue;
    chosen_terms[j] = static_cast<std::uint32_t>(terms.size());
    terms.push_back(evaluate_observation(
        a.sensor, to_gaussian(a.map.at(static_cast<memory::Slot>(a.assignment[j]))), a.pose,
        a.scan[j].z, a.in.r));
  }
  MapUpdateScratch scratch;
  MapUpdateCounts counts_a, counts_b;
  update_particle_map<false>(a.in, a.pose, a.scan, a.assignment, terms, chosen_terms, a.map,
                             scratch, counts_a);
  update_particle_map<true>(b.in, b.pose, b.scan, b.assignment, {}, {}, b.map, scratch, counts_b);
  ASSERT_EQ(a.map.size(), b.map.size());
  for (const auto [slot, l] : a.map) {
    const memory::Landmark& other = b.map.at(slot);
    EXPECT_EQ(l.x, other.x);
    EXPECT_EQ(l.sxy, other.sxy);
    EXPECT_EQ(l.log_odds, other.log_odds);
  }
}

// Data association sampling under a detection probability below one: every confirmed landmark
// in view that no observation took is a missed detection, ln(1 - P_D) in the particle's weight
// (counted before negative information lowers it); the map changes as without the factor, and
// the factor stays when negative information is off.
TEST(MapUpdateTest, MissedDetectionsAreTheConfirmedLandmarksInViewLeftUntaken) {
  const double log_missed = std::log1p(-0.7);
  std::size_t missed = 0;
  std::size_t provisional = 0;
  {
    const World w;
    for (const auto& [slot, l] : w.oracle) {
      if (!w.in_view(l)) continue;
      if (std::find(w.assignment.begin(), w.assignment.end(), slot) != w.assignment.end()) continue;
      if (l.log_odds >= w.in.existence.confirm_at) {
        ++missed;
      } else {
        ++provisional;
      }
    }
  }
  ASSERT_GT(missed, 2u);
  ASSERT_GT(provisional, 2u);
  for (const bool negative : {true, false}) {
    World with, without;
    with.in.log_missed = log_missed;
    with.in.existence.negative_information = without.in.existence.negative_information = negative;
    MapUpdateScratch scratch;
    MapUpdateCounts counts_with, counts_without;
    const double got = update_particle_map<true>(with.in, with.pose, with.scan, with.assignment, {},
                                                 {}, with.map, scratch, counts_with);
    EXPECT_EQ(got, static_cast<double>(missed) * log_missed) << negative;
    EXPECT_EQ(update_particle_map<true>(without.in, without.pose, without.scan, without.assignment,
                                        {}, {}, without.map, scratch, counts_without),
              0.0);
    EXPECT_EQ(counts_with.removed, counts_without.removed);
    EXPECT_EQ(negative, counts_with.removed > 0);
    ASSERT_EQ(with.map.size(), without.map.size());
    for (const auto [slot, l] : with.map) EXPECT_EQ(l, without.map.at(slot));
  }
}

// Twin merging (LoopClosureConfig::merge_gate). One observation is taken by landmark C; landmark O,
// another candidate of that observation, lies at `offset` from C's updated mean. The oracle:
// C updated by the scalar EKF; the squared distance under C's and O's covariances; the
// better-known of C updated and O updated by the same observation kept in C's slot.
struct TwinWorld {
  memory::PoolHeap heap;
  memory::ParticleMap map{heap, memory::Indexing::kSpatial};
  RangeBearingModel sensor{SensorOffset{0.3, 0.0, 0.1}};
  MapUpdateInput in;
  Pose pose{2.0, 1.0, 0.4};
  std::vector<PlannedObservation> scan;
  std::vector<std::int64_t> assignment;
  std::vector<AssociationCandidate> candidates;
  memory::Landmark chosen{9.0, 4.0, 0.02, 0.004, 0.03, 3.0, 900 << 20, 17};
  memory::Landmark other{0, 0, 0.002, -0.0005, 0.001, 2.5, 40 << 20, 4};
  memory::Slot c = 0, o = 0;
  LandmarkGaussian c_updated;  // the oracle's C after the observation

  TwinWorld() {
    in.sensor = &sensor;
    in.r << 0.01, 0, 0, 0.0004;
    in.existence.confirm_at = 2.0;
    in.max_range = 30.0;
    in.field_of_view = 3.0;
    in.scan_step = 1000;
    in.merge_gate = 9.21;
    PlannedObservation z;
    z.z = sensor.predict({chosen.x + 0.03, chosen.y - 0.02}, pose);
    scan.push_back(z);
    c_updated = to_gaussian(chosen);
    update_landmark(sensor, c_updated, pose, z.z, in.r);
  }
  // The squared distance of O at c_updated.mean + offset, as the merge must compute it.
  double distance2(const Eigen::Vector2d& offset) const {
    const Eigen::Matrix2d spread = c_updated.cov + to_gaussian(other).cov;
    return offset.dot(spread.inverse() * offset);
  }
  // Places O, then runs the update with the observation taken by C and O its other candidate.
  void run(const Eigen::Vector2d& offset, MapUpdateCounts& counts) {
    other.x = c_updated.mean[0] + offset[0];
    other.y = c_updated.mean[1] + offset[1];
    c = map.insert(chosen, largest_variance(chosen));
    o = map.insert(other, largest_variance(other));
    if (assignment.empty()) assignment.push_back(c);
    candidates = {{0, o, -3.0, 0, 1.0f}, {0, c, -2.0, 0, 0.5f}};
    MapUpdateScratch scratch;
    update_particle_map<true>(in, pose, scan, assignment, {}, {}, map, scratch, counts, candidates);
  }
};

TEST(MapUpdateTest, ATwinWithinTheGateGoesAndTheBetterKnownEstimateStays) {
  TwinWorld w;
  const Eigen::Vector2d offset(0.05, 0.02);
  ASSERT_LT(w.distance2(offset), w.in.merge_gate);
  MapUpdateCounts counts;
  w.run(offset, counts);
  EXPECT_EQ(w.map.find(w.o), nullptr);
  ASSERT_NE(w.map.find(w.c), nullptr);
  EXPECT_EQ(counts.removed, 1u);
  // O (covariance determinant ~2e-6) is better known than C (~6e-4): its estimate, updated by
  // the observation, goes to C's slot, which keeps C's id and takes C's larger log-odds.
  LandmarkGaussian want = to_gaussian(w.other);
  update_landmark(w.sensor, want, w.pose, w.scan[0].z, w.in.r);
  const memory::Landmark& got = w.map.at(w.c);
  EXPECT_NEAR(got.x, want.mean[0], 1e-12);
  EXPECT_NEAR(got.y, want.mean[1], 1e-12);
  EXPECT_NEAR(got.sxx, want.cov(0, 0), 1e-15);
  EXPECT_NEAR(got.sxy, want.cov(0, 1), 1e-15);
  EXPECT_NEAR(got.syy, want.cov(1, 1), 1e-15);
  EXPECT_EQ(got.id, w.chosen.id);
  EXPECT_EQ(got.log_odds, w.chosen.log_odds + w.in.existence.seen);
  EXPECT_EQ(got.last_seen, 1000);
  expect_index_is_the_map(w.map);
}

TEST(MapUpdateTest, TheChosenEstimateStaysWhenItIsTheBetterKnown) {
  TwinWorld w;
  w.other.sxx = 0.2;  // O far less certain than C
  w.other.sxy = 0.0;
  w.other.syy = 0.3;
  w.other.log_odds = 6.0;
  const Eigen::Vector2d offset(-0.1, 0.2);
  ASSERT_LT(w.distance2(offset), w.in.merge_gate);
  MapUpdateCounts counts;
  w.run(offset, counts);
  EXPECT_EQ(w.map.find(w.o), nullptr);
  const memory::Landmark& got = w.map.at(w.c);
  EXPECT_NEAR(got.x, w.c_updated.mean[0], 1e-12);
  EXPECT_NEAR(got.syy, w.c_updated.cov(1, 1), 1e-15);
  EXPECT_EQ(got.id, w.chosen.id);
  EXPECT_EQ(got.log_odds, 6.0);  // the other's, the larger
  expect_index_is_the_map(w.map);
}

TEST(MapUpdateTest, TheMergeGateIsTheSpreadOfBoth) {
  for (const double angle : {0.0, 0.7, 1.9, 3.0, 4.4}) {
    const Eigen::Vector2d u(std::cos(angle), std::sin(angle));
    TwinWorld probe;
    const double at_gate = std::sqrt(probe.in.merge_gate / probe.distance2(u));
    for (const double f : {0.98, 1.02}) {
      TwinWorld w;
      MapUpdateCounts counts;
      w.run(f * at_gate * u, counts);
      EXPECT_EQ(w.map.find(w.o) == nullptr, f < 1.0) << angle << " " << f;
    }
  }
}

TEST(MapUpdateTest, OnlyConfirmedTwinsThatNoOtherObservationTookMerge) {
  const Eigen::Vector2d offset(0.05, 0.02);
  {
    TwinWorld w;  // O provisional
    w.other.log_odds = 1.5;
    MapUpdateCounts counts;
    w.run(offset, counts);
    EXPECT_NE(w.map.find(w.o), nullptr);
  }
  {
    TwinWorld w;  // C provisional (confirmed only from this scan on)
    w.chosen.log_odds = 0.5;
    MapUpdateCounts counts;
    w.run(offset, counts);
    EXPECT_NE(w.map.find(w.o), nullptr);
  }
  {
    TwinWorld w;  // merging off
    w.in.merge_gate = 0.0;
    MapUpdateCounts counts;
    w.run(offset, counts);
    EXPECT_NE(w.map.find(w.o), nullptr);
  }
  {
    TwinWorld w;  // O taken by a second observation: two landmarks, as far as this scan knows
    PlannedObservation z;
    z.z = w.sensor.predict({w.c_updated.mean[0] + 0.05, w.c_updated.mean[1] + 0.02}, w.pose);
    w.scan.push_back(z);
    w.assignment = {0, 1};  // the slots the two inserts below get
    MapUpdateCounts counts;
    w.run(offset, counts);
    ASSERT_EQ(w.assignment[0], static_cast<std::int64_t>(w.c));
    ASSERT_EQ(w.assignment[1], static_cast<std::int64_t>(w.o));
    EXPECT_NE(w.map.find(w.o), nullptr);
    EXPECT_NE(w.map.find(w.c), nullptr);
  }
}

TEST(MapUpdateTest, AMapRebuiltFromItsTreeIndexesEverySlot) {
  World w;
  const memory::ParticleMap rebuilt(w.map.tree(), memory::Indexing::kSpatial, largest_variance);
  expect_index_is_the_map(rebuilt);
}

}  // namespace
}  // namespace fastslam::engine::internal
