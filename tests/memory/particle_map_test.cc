// ParticleMap against an oracle: a std::map of landmarks (with each one's extent) copied the
// naive way, and brute-force radius and footprint queries over it. Random sequences of insert,
// update (moving or not), erase and copy run on several maps that share nodes, in both indexing
// modes; after every step each map's tree equals its oracle and its index answers as the
// brute force does. Injected allocation failures leave a map unchanged.
#include "memory/particle_map.h"

#include <cmath>
#include <cstdint>
#include <iterator>
#include <map>
#include <new>
#include <random>
#include <stdexcept>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "memory/landmark_tree.h"
#include "memory/node_heap.h"
#include "memory/spatial_index.h"
#include "tests/memory/heap_fixtures.h"

namespace fastslam::memory {
namespace {

using testing::Oracle;
using testing::same_contents;
using testing::sized;

// The oracle of one map: its landmarks, and the extent each index entry holds.
struct NaiveMap {
  Oracle landmarks;
  std::map<Slot, float> extents;
};

// The extent the tests store: a function of the landmark, as the engine's eigenvalue is.
float extent_of(const Landmark& l) { return static_cast<float>(std::fabs(l.sxx)); }

// Entries within `radius` of (x, y), as (slot, extent), by brute force.
std::map<Slot, float> brute_within(const NaiveMap& naive, double x, double y, double radius) {
  std::map<Slot, float> hits;
  for (const auto& [slot, l] : naive.landmarks) {
    const double dx = l.x - x;
    const double dy = l.y - y;
    if (dx * dx + dy * dy <= radius * radius) hits[slot] = naive.extents.at(slot);
  }
  return hits;
}

::testing::AssertionResult matches(const ParticleMap& map, const NaiveMap& naive,
                                   std::mt19937_64& rng) {
  auto same = same_contents(map.tree(), naive.landmarks);
  if (!same) return same;
  if (map.size() != naive.landmarks.size()) return ::testing::AssertionFailure() << "size";
  if (!map.indexed()) {
    return map.index().empty() ? ::testing::AssertionSuccess()
                               : ::testing::AssertionFailure() << "unindexed map has entries";
  }
  if (map.index().size() != naive.landmarks.size()) {
    return ::testing::AssertionFailure() << "index size " << map.index().size();
  }
  std::uniform_real_distribution<double> at(-120.0, 120.0);
  std::uniform_real_distribution<double> radius(0.0, 60.0);
  for (int q = 0; q < 6; ++q) {
    const double x = at(rng);
    const double y = at(rng);
    const double r = q == 0 ? 1e3 : radius(rng);
    std::map<Slot, float> hits;
    bool exact = true;
    map.index().within(x, y, r, [&](const SpatialEntry& e) {
      const Landmark* l = map.find(e.slot);
      exact = exact && l != nullptr && l->x == e.x && l->y == e.y;
      exact = exact && hits.emplace(e.slot, e.extent).second;
    });
    if (!exact) return ::testing::AssertionFailure() << "an entry is not at its landmark";
    if (hits != brute_within(naive, x, y, r)) {
      return ::testing::AssertionFailure() << "within(" << x << ", " << y << ", " << r << ")";
    }
  }
  return ::testing::AssertionSuccess();
}

Landmark random_landmark(std::mt19937_64& rng, std::uint64_t id) {
  Landmark l = testing::random_landmark(rng, id);
  // Some landmarks on one point: equal positions must stay distinct entries.
  if (rng() % 8 == 0) l.x = l.y = 5.0;
  return l;
}

class ParticleMapTest : public testing::HeapLeakCheck<testing::Config<DefaultTreePolicy, PoolHeap>>,
                        public ::testing::WithParamInterface<Indexing> {};

INSTANTIATE_TEST_SUITE_P(Modes, ParticleMapTest,
                         ::testing::Values(Indexing::kNone, Indexing::kSpatial),
                         [](const ::testing::TestParamInfo<Indexing>& param_info) {
                           return param_info.param == Indexing::kNone ? "Unindexed" : "Indexed";
                         });

TEST_P(ParticleMapTest, RandomSequencesMatchTheOracle) {
  constexpr std::size_t kMaps = 6;
  const int steps = sized(4000, 600);
  std::mt19937_64 rng(2024);
  std::vector<ParticleMap> maps(kMaps, ParticleMap(heap_, GetParam()));
  std::vector<NaiveMap> naive(kMaps);
  std::uint64_t next_id = 0;
  for (int step = 0; step < steps; ++step) {
    const std::size_t k = rng() % kMaps;
    ParticleMap& map = maps[k];
    NaiveMap& oracle = naive[k];
    const int kind = static_cast<int>(rng() % 10);
    if (kind < 4 || oracle.landmarks.empty()) {
      const Landmark l = random_landmark(rng, next_id++);
      const Slot slot = map.insert(l, extent_of(l));
      ASSERT_EQ(slot, testing::lowest_free(oracle.landmarks));
      oracle.landmarks[slot] = l;
      oracle.extents[slot] = extent_of(l);
    } else if (kind == 9) {
      // Copy another map over this one (shares its nodes; both then diverge).
      const std::size_t from = rng() % kMaps;
      map = maps[from];
      oracle = naive[from];
      EXPECT_TRUE(map.shares_root_with(maps[from]));
    } else {
      auto it = oracle.landmarks.begin();
      std::advance(it, static_cast<std::ptrdiff_t>(rng() % oracle.landmarks.size()));
      const Slot slot = it->first;
      if (kind < 7) {
        // An update: a new mean (moving the entry, with the new extent) or other fields only
        // (the entry keeps its extent).
        Landmark next = it->second;
        const bool moves = kind < 6;
        next.sxx += 1.0;
        next.log_odds -= 0.5;
        if (moves) {
          next.x += std::uniform_real_distribution<double>(-30.0, 30.0)(rng);
          next.y += std::uniform_real_distribution<double>(-30.0, 30.0)(rng);
        }
        int extent_calls = 0;
        map.update(
            slot, [&](Landmark& l) { l = next; },
            [&](const Landmark& l) {
              ++extent_calls;
              return extent_of(l);
            });
        EXPECT_EQ(extent_calls, moves && map.indexed() ? 1 : 0);
        it->second = next;
        if (moves) oracle.extents[slot] = extent_of(next);
      } else {
        map.erase(slot);
        oracle.landmarks.erase(it);
        oracle.extents.erase(slot);
      }
    }
    ASSERT_TRUE(matches(map, oracle, rng)) << "step " << step << ", map " << k;
  }
  for (std::size_t k = 0; k < kMaps; ++k) EXPECT_TRUE(matches(maps[k], naive[k], rng));
}

// update_each: runs of updates (moving by centimetres or metres, or not at all) of a few
// landmarks, on a map that shares its nodes with a copy taken before each run, as the same
// updates one by one on the oracle; the copies keep their contents.
TEST_P(ParticleMapTest, UpdateEachMatchesUpdatesOneByOne) {
  std::mt19937_64 rng(77);
  ParticleMap map(heap_, GetParam());
  NaiveMap oracle;
  for (std::uint64_t id = 0; id < 300; ++id) {
    const Landmark l = random_landmark(rng, id);
    const Slot slot = map.insert(l, extent_of(l));
    oracle.landmarks[slot] = l;
    oracle.extents[slot] = extent_of(l);
  }
  std::uniform_real_distribution<double> step(-1.0, 1.0);
  for (int run = 0; run < sized(200, 40); ++run) {
    std::vector<ParticleMap> copies{map};
    std::vector<NaiveMap> copy_oracles{oracle};
    std::vector<Slot> slots;
    for (std::size_t k = 0, n = 1 + rng() % 10; k < n; ++k) {
      auto it = oracle.landmarks.begin();
      std::advance(it, static_cast<std::ptrdiff_t>(rng() % oracle.landmarks.size()));
      if (std::find(slots.begin(), slots.end(), it->first) == slots.end()) {
        slots.push_back(it->first);
      }
    }
    std::vector<Landmark> next;
    for (const Slot slot : slots) {
      Landmark l = oracle.landmarks.at(slot);
      const double scale = rng() % 3 == 0 ? 20.0 : 0.01;
      if (rng() % 5 != 0) {
        l.x += scale * step(rng);
        l.y += scale * step(rng);
      }
      l.sxx += 0.5;
      next.push_back(l);
    }
    map.update_each(
        slots, [&](std::size_t k, Landmark& l) { l = next[k]; }, extent_of);
    for (std::size_t k = 0; k < slots.size(); ++k) {
      const bool moved = next[k].x != oracle.landmarks.at(slots[k]).x ||
                         next[k].y != oracle.landmarks.at(slots[k]).y;
      oracle.landmarks[slots[k]] = next[k];
      if (moved) oracle.extents[slots[k]] = extent_of(next[k]);
    }
    ASSERT_TRUE(matches(map, oracle, rng)) << "run " << run;
    for (std::size_t c = 0; c < copies.size(); ++c) {
      ASSERT_TRUE(matches(copies[c], copy_oracles[c], rng)) << "run " << run << ", copy " << c;
    }
  }
}

TEST_P(ParticleMapTest, BuiltFromATreeIndexesItsLandmarksInSlotOrder) {
  std::mt19937_64 rng(5);
  LandmarkTree tree(heap_);
  NaiveMap naive;
  for (std::uint64_t i = 0; i < 300; ++i) {
    const Landmark l = random_landmark(rng, i);
    naive.landmarks[tree.insert(l)] = l;
  }
  for (Slot hole : {Slot{3}, Slot{77}, Slot{200}}) {
    tree.erase(hole);
    naive.landmarks.erase(hole);
  }
  for (const auto& [slot, l] : naive.landmarks) naive.extents[slot] = extent_of(l);
  const ParticleMap map(tree, GetParam(), extent_of);
  EXPECT_EQ(map.indexing(), GetParam());
  EXPECT_TRUE(map.tree().shares_root_with(tree));
  EXPECT_TRUE(matches(map, naive, rng));
  // Inserting takes the lowest free slot, as the tree does.
  ParticleMap copy = map;
  EXPECT_EQ(copy.insert(Landmark{}, 0.0f), Slot{3});
  EXPECT_TRUE(matches(map, naive, rng));
}

// A map rebuilt beside a near one (the loader's way) holds the same landmarks and answers as
// one built from scratch, with fresh extents; it shares the near map's index where the two
// maps agree, so a particle set rebuilt this way takes far fewer index nodes.
TEST_P(ParticleMapTest, RebuiltBesideANearMapAnswersAsFromScratch) {
  std::mt19937_64 rng(31);
  std::vector<ParticleMap> maps(1, ParticleMap(heap_, GetParam()));
  for (std::uint64_t id = 0; id < 2000; ++id) {
    const Landmark l = random_landmark(rng, id);
    maps[0].insert(l, extent_of(l));
  }
  for (int i = 1; i < 30; ++i) {
    ParticleMap map = maps[rng() % maps.size()];
    for (int c = 0, n = static_cast<int>(rng() % 6); c < n; ++c) {
      auto it = map.begin();
      for (std::uint64_t skip = rng() % map.size(); skip > 0; --skip) ++it;
      const Slot slot = (*it).slot;
      const int kind = static_cast<int>(rng() % 4);
      if (kind == 0) {
        map.erase(slot);
      } else if (kind == 1) {
        const Landmark l = random_landmark(rng, 1000 + i);
        map.insert(l, extent_of(l));
      } else {
        // Moved, or only its covariance changed (the stored extent goes stale).
        map.update(
            slot,
            [&](Landmark& l) {
              l.sxx += 2.0;
              if (kind == 2) l.x += 0.5;
            },
            extent_of);
      }
    }
    maps.push_back(map);
  }
  const std::int64_t before = heap_.stats().live_nodes;
  std::vector<ParticleMap> scratch;
  for (const ParticleMap& m : maps) scratch.emplace_back(m.tree(), GetParam(), extent_of);
  const std::int64_t scratch_nodes = heap_.stats().live_nodes - before;
  scratch.clear();
  std::vector<ParticleMap> near;
  near.emplace_back(maps[0].tree(), GetParam(), extent_of);
  std::uint64_t steps = ~std::uint64_t{0};
  for (std::size_t i = 1; i < maps.size(); ++i) {
    near.emplace_back(maps[i].tree(), near[i - 1], extent_of, steps);
  }
  const std::int64_t near_nodes = heap_.stats().live_nodes - before;
  for (std::size_t i = 0; i < maps.size(); ++i) {
    EXPECT_EQ(near[i].indexing(), GetParam());
    NaiveMap oracle;
    for (const auto [slot, l] : maps[i]) {
      oracle.landmarks[slot] = l;
      oracle.extents[slot] = extent_of(l);
    }
    ASSERT_TRUE(matches(near[i], oracle, rng)) << "map " << i;
  }
  if (GetParam() == Indexing::kSpatial) {
    EXPECT_LT(near_nodes * 4, scratch_nodes) << "near " << near_nodes << ", scratch " << scratch_nodes;
    // A bounded rebuild stops once its steps run out (and frees what it made).
    std::uint64_t few = 3;
    const ParticleMap empty(heap_, GetParam());
    EXPECT_THROW(ParticleMap(maps[0].tree(), empty, extent_of, few), std::length_error);
    EXPECT_EQ(few, 0u);
  } else {
    EXPECT_EQ(near_nodes, 0);
  }
}

TEST_P(ParticleMapTest, FailedChangesLeaveTheMapUnchanged) {
  testing::FailingHeap failing(heap_);
  std::mt19937_64 rng(11);
  ParticleMap map(failing, GetParam());
  NaiveMap naive;
  for (std::uint64_t i = 0; i < 200; ++i) {
    const Landmark l = random_landmark(rng, i);
    const Slot slot = map.insert(l, extent_of(l));
    naive.landmarks[slot] = l;
    naive.extents[slot] = extent_of(l);
  }
  // A copy shares every node, so each change below must copy paths (and may fail doing so).
  for (int attempt = 0; attempt < 60; ++attempt) {
    const ParticleMap keep = map;
    const int kind = attempt % 3;
    const Slot slot = static_cast<Slot>(rng() % 200);
    if (naive.landmarks.count(slot) == 0) continue;
    for (std::int64_t k = 1;; ++k) {
      failing.fail_at(k);
      bool threw = false;
      try {
        if (kind == 0) {
          map.insert(Landmark{.x = 1e3, .y = -1e3}, 1.0f);
        } else if (kind == 1) {
          map.update(
              slot, [](Landmark& l) { l.x += 200.0; }, extent_of);
        } else {
          map.erase(slot);
        }
      } catch (const std::bad_alloc&) {
        threw = true;
      }
      failing.disarm();
      if (!threw) break;
      ASSERT_TRUE(matches(map, naive, rng)) << "kind " << kind << ", failure " << k;
    }
    // Undo through the oracle: the change succeeded; take the kept copy back.
    map = keep;
  }
  EXPECT_TRUE(matches(map, naive, rng));
}

TEST_P(ParticleMapTest, RefusesBadSlotsAndPositionsWithoutChange) {
  std::mt19937_64 rng(3);
  ParticleMap map(heap_, GetParam());
  NaiveMap naive;
  const Landmark l = random_landmark(rng, 1);
  naive.landmarks[map.insert(l, 2.0f)] = l;
  naive.extents[0] = 2.0f;
  EXPECT_THROW(map.erase(5), std::out_of_range);
  EXPECT_THROW(map.update(
                   7, [](Landmark&) {}, extent_of),
               std::out_of_range);
  // A change that throws, or (indexed) moves to a position the index refuses.
  EXPECT_THROW(map.update(
                   0,
                   [](Landmark& m) {
                     m.x = 1.0;
                     throw std::runtime_error("refused");
                   },
                   extent_of),
               std::runtime_error);
  if (map.indexed()) {
    EXPECT_THROW(map.update(
                     0, [](Landmark& m) { m.x = std::nan(""); }, extent_of),
                 std::invalid_argument);
    EXPECT_THROW(map.edit_unindexed(0), std::logic_error);
    EXPECT_THROW(map.insert(Landmark{.x = 1e200}, 0.0f), std::invalid_argument);
  } else {
    map.edit_unindexed(0).log_odds = 9.0;
    naive.landmarks[0].log_odds = 9.0;
  }
  EXPECT_TRUE(matches(map, naive, rng));
}

}  // namespace
}  // namespace fastslam::memory
