// The structure-of-arrays particle store: construction, column alignment, and `gather`
// (resampling) against a naive oracle - particle k of the result is a full copy of particle
// index[k] (columns, the covariance column when carried, and a std::map per particle, whose
// spatial index, when the store keeps one, holds exactly the landmarks' means). The maps no
// survivor holds are freed exactly (node counts computed from the slots), bad indices are refused
// with the store unchanged, and gather runs inside a two-thread task_arena, between parallel
// per-particle edits, and in several stores sharing maps at once. Labelled "concurrency"
// (ThreadSanitizer runs it too).
#include "memory/particle_store.h"

#include <algorithm>
#include <cstdint>
#include <iterator>
#include <random>
#include <set>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <oneapi/tbb/task_arena.h>

#include "memory/landmark_tree.h"
#include "memory/node_heap.h"
#include "memory/particle_map.h"
#include "tests/memory/heap_fixtures.h"

namespace fastslam::memory {
namespace {

using testing::Config;
using testing::dense_node_count;
using testing::lowest_free;
using testing::Oracle;
using testing::path_union;
using testing::run_tasks;
using testing::same_contents;
using testing::sized;
using testing::tagged_landmark;

// The naive particle: every column value and a whole std::map.
struct NaiveParticle {
  double x = 0, y = 0, theta = 0, v = 0, omega = 0, log_weight = 0;
  Oracle map;
};

constexpr StoreOptions kIndexed{Indexing::kSpatial, PoseCovariance::kNone};

float no_extent(const Landmark&) { return 0.0f; }

// A particle map holding the landmarks of `tree` (shared), in the given mode.
ParticleMap map_of(const LandmarkTree& tree, Indexing indexing) {
  return ParticleMap(tree, indexing, no_extent);
}

// The index of an indexed map holds one entry per landmark, at its mean; an unindexed one none.
::testing::AssertionResult index_in_step(const ParticleMap& map) {
  if (!map.indexed()) {
    return map.index().empty() ? ::testing::AssertionSuccess()
                               : ::testing::AssertionFailure() << "unindexed map has entries";
  }
  if (map.index().size() != map.size()) {
    return ::testing::AssertionFailure()
           << "index size " << map.index().size() << ", map size " << map.size();
  }
  std::set<Slot> seen;
  bool ok = true;
  map.index().for_each([&](const SpatialEntry& e) {
    const Landmark* l = map.find(e.slot);
    ok = ok && l != nullptr && l->x == e.x && l->y == e.y && seen.insert(e.slot).second;
  });
  return ok ? ::testing::AssertionSuccess()
            : ::testing::AssertionFailure() << "an entry is not at its landmark's mean";
}

template <class C>
class ParticleStoreTest : public testing::HeapLeakCheck<C> {
 protected:
  // Sets particle k's columns to values derived from (k, salt).
  static void set_columns(ParticleStore& store, std::size_t k, double salt, NaiveParticle& p) {
    const double base = static_cast<double>(k) + salt;
    store.x()[k] = p.x = base;
    store.y()[k] = p.y = base + 0.1;
    store.theta()[k] = p.theta = base + 0.2;
    store.v()[k] = p.v = base + 0.3;
    store.omega()[k] = p.omega = base + 0.4;
    store.log_weight()[k] = p.log_weight = -base;
  }
  static ::testing::AssertionResult matches(const ParticleStore& store,
                                            const std::vector<NaiveParticle>& naive) {
    if (store.size() != naive.size()) {
      return ::testing::AssertionFailure() << "size " << store.size() << " vs " << naive.size();
    }
    for (std::size_t k = 0; k < naive.size(); ++k) {
      const NaiveParticle& p = naive[k];
      if (store.x()[k] != p.x || store.y()[k] != p.y || store.theta()[k] != p.theta ||
          store.v()[k] != p.v || store.omega()[k] != p.omega ||
          store.log_weight()[k] != p.log_weight) {
        return ::testing::AssertionFailure() << "columns of particle " << k;
      }
      if (store.landmark_count(k) != p.map.size()) {
        return ::testing::AssertionFailure() << "landmark count of particle " << k;
      }
      auto same = same_contents(store.map(k).tree(), p.map);
      if (!same) return same << " (particle " << k << ")";
      auto in_step = index_in_step(store.map(k));
      if (!in_step) return in_step << " (particle " << k << ")";
    }
    return ::testing::AssertionSuccess();
  }
  static std::vector<NaiveParticle> naive_gather(const std::vector<NaiveParticle>& from,
                                                 const std::vector<std::uint32_t>& index) {
    std::vector<NaiveParticle> to;
    for (std::uint32_t i : index) to.push_back(from[i]);  // the whole map, copied
    return to;
  }
  // Systematic-resampling-like indices: sorted, some particles repeated, some gone.
  static std::vector<std::uint32_t> random_index(std::mt19937_64& rng, std::size_t from,
                                                 std::size_t to) {
    std::vector<std::uint32_t> index(to);
    for (auto& i : index) i = static_cast<std::uint32_t>(rng() % (from / 3 + 1));
    for (std::size_t k = 0; k < to; k += 5) index[k] = static_cast<std::uint32_t>(rng() % from);
    return index;
  }
  // Random edits/inserts/erases of particle k's map, mirrored in the naive particle.
  static void mutate(ParticleStore& store, std::size_t k, NaiveParticle& p, std::mt19937_64& rng,
                     int ops) {
    for (int op = 0; op < ops; ++op) {
      const int kind = static_cast<int>(rng() % 3);
      if (kind == 0 || p.map.size() < 4) {
        const Slot expected = lowest_free(p.map);
        const Landmark l = tagged_landmark(k, static_cast<Slot>(rng() & 0xfff));
        EXPECT_EQ(store.map(k).insert(l, 0.5f), expected);
        p.map[expected] = l;
      } else {
        auto it = p.map.begin();
        std::advance(it, static_cast<std::ptrdiff_t>(rng() % p.map.size()));
        if (kind == 1) {
          store.map(k).update(
              it->first, [](Landmark& l) { l.y += 1.0; }, no_extent);
          it->second.y += 1.0;
        } else {
          store.map(k).erase(it->first);
          p.map.erase(it);
        }
      }
    }
  }
};

using Configs =
    ::testing::Types<Config<DefaultTreePolicy, MallocHeap>, Config<DefaultTreePolicy, PoolHeap>>;
TYPED_TEST_SUITE(ParticleStoreTest, Configs, testing::ConfigName);

TYPED_TEST(ParticleStoreTest, NewStoreHasParticlesAtTheOriginWithEmptyMaps) {
  ParticleStore store(37, this->heap_);
  EXPECT_EQ(store.size(), 37u);
  EXPECT_EQ(&store.heap(), &this->heap_);
  const ParticleStore& view = store;
  for (std::size_t k = 0; k < store.size(); ++k) {
    EXPECT_EQ(view.x()[k], 0.0);
    EXPECT_EQ(view.y()[k], 0.0);
    EXPECT_EQ(view.theta()[k], 0.0);
    EXPECT_EQ(view.v()[k], 0.0);
    EXPECT_EQ(view.omega()[k], 0.0);
    EXPECT_EQ(view.log_weight()[k], 0.0);
    EXPECT_TRUE(view.map(k).empty());
    EXPECT_EQ(view.landmark_count(k), 0u);
    EXPECT_EQ(&view.map(k).heap(), &this->heap_);
  }
  EXPECT_EQ(this->heap_.stats().allocations, 0);
  ParticleStore none(0, this->heap_);
  EXPECT_EQ(none.size(), 0u);
}

TYPED_TEST(ParticleStoreTest, ColumnsAreCacheLineAligned) {
  ParticleStore store(101, this->heap_);
  for (auto column :
       {store.x(), store.y(), store.theta(), store.v(), store.omega(), store.log_weight()}) {
    EXPECT_EQ(column.size(), 101u);
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(column.data()) % 64, 0u);
  }
  store.gather(std::vector<std::uint32_t>(77, 3));
  EXPECT_EQ(reinterpret_cast<std::uintptr_t>(store.log_weight().data()) % 64, 0u);
}

TYPED_TEST(ParticleStoreTest, GatherCopiesEveryColumnAndSharesEveryMap) {
  constexpr std::size_t kParticles = 9;
  ParticleStore store(kParticles, this->heap_);
  std::vector<NaiveParticle> naive(kParticles);
  for (std::size_t k = 0; k < kParticles; ++k) {
    this->set_columns(store, k, 0.5, naive[k]);
    for (Slot s = 0; s <= k * 3; ++s) {
      store.map(k).insert(tagged_landmark(k, s), 0.0f);
      naive[k].map[s] = tagged_landmark(k, s);
    }
  }
  ASSERT_TRUE(this->matches(store, naive));
  std::vector<ParticleMap> old_maps;
  for (std::size_t k = 0; k < kParticles; ++k) old_maps.push_back(store.map(k));
  const std::vector<std::uint32_t> index = {3, 3, 0, 8, 2, 2, 2, 5, 7, 7, 1};
  const std::int64_t allocations = this->heap_.stats().allocations;
  store.gather(index);
  EXPECT_EQ(this->heap_.stats().allocations, allocations);  // sharing, not copying
  naive = this->naive_gather(naive, index);
  EXPECT_TRUE(this->matches(store, naive));
  for (std::size_t k = 0; k < index.size(); ++k) {
    EXPECT_TRUE(store.map(k).shares_root_with(old_maps[index[k]])) << "particle " << k;
  }
  // Copies diverge on their own: editing particle 0 leaves particle 1 (same ancestor) alone.
  store.map(0).edit_unindexed(0).x = 1e9;
  naive[0].map[0].x = 1e9;
  EXPECT_TRUE(this->matches(store, naive));
}

// The spatial index column travels with its particle: shared by root, entries unchanged, and
// the indices no survivor holds are freed.
TYPED_TEST(ParticleStoreTest, GatherSharesEverySpatialIndex) {
  constexpr std::size_t kParticles = 6;
  ParticleStore store(kParticles, this->heap_, kIndexed);
  std::vector<std::set<std::pair<Slot, double>>> naive(kParticles);
  for (std::size_t k = 0; k < kParticles; ++k) {
    for (Slot s = 0; s < 40 * (k + 1); ++s) {
      const double x = static_cast<double>(k * 1000 + s);
      EXPECT_EQ(store.map(k).insert(Landmark{.x = x, .y = -x}, 0.0f), s);
      naive[k].insert({s, x});
    }
  }
  std::vector<ParticleMap> old;
  for (std::size_t k = 0; k < kParticles; ++k) old.push_back(store.map(k));
  const std::vector<std::uint32_t> index = {4, 4, 1, 0};
  store.gather(index);
  old.clear();  // only the survivors' indices hold nodes now
  for (std::size_t k = 0; k < index.size(); ++k) {
    std::set<std::pair<Slot, double>> entries;
    EXPECT_TRUE(index_in_step(store.map(k)));
    store.map(k).index().for_each([&](const SpatialEntry& e) {
      EXPECT_EQ(e.y, -e.x);
      entries.insert({e.slot, e.x});
    });
    EXPECT_EQ(entries, naive[index[k]]) << "particle " << k;
  }
  EXPECT_TRUE(store.map(0).shares_root_with(store.map(1)));
  store.map(0).erase(0);  // copies diverge on their own
  EXPECT_EQ(store.map(0).index().size() + 1, store.map(1).index().size());
  EXPECT_TRUE(index_in_step(store.map(0)));
  store.gather({});
  EXPECT_EQ(this->heap_.stats().live_nodes, 0);
}

TYPED_TEST(ParticleStoreTest, GatherResizesTheStore) {
  ParticleStore store(4, this->heap_);
  std::vector<NaiveParticle> naive(4);
  for (std::size_t k = 0; k < 4; ++k) {
    this->set_columns(store, k, 0.0, naive[k]);
    store.map(k).insert(tagged_landmark(k, 0), 0.0f);
    naive[k].map[0] = tagged_landmark(k, 0);
  }
  for (const std::vector<std::uint32_t>& index :
       {std::vector<std::uint32_t>{0, 1, 2, 3, 3, 2, 1, 0, 0, 0}, std::vector<std::uint32_t>{9, 4},
        std::vector<std::uint32_t>{1}, std::vector<std::uint32_t>{0, 0, 0}}) {
    store.gather(index);
    naive = this->naive_gather(naive, index);
    ASSERT_TRUE(this->matches(store, naive));
  }
  store.gather({});  // no particle left: every map is freed
  EXPECT_EQ(store.size(), 0u);
  EXPECT_EQ(this->heap_.stats().live_nodes, 0);
  store.gather({});
  EXPECT_THROW(store.gather(std::vector<std::uint32_t>{0}), std::invalid_argument);
}

TYPED_TEST(ParticleStoreTest, EveryGrainGivesTheSameResult) {
  std::mt19937_64 rng(8);
  for (std::size_t grain : {0u, 1u, 3u, 64u, 100000u}) {
    ParticleStore store(150, this->heap_);
    std::vector<NaiveParticle> naive(150);
    for (std::size_t k = 0; k < 150; ++k) {
      this->set_columns(store, k, static_cast<double>(grain), naive[k]);
      this->mutate(store, k, naive[k], rng, 5);
    }
    for (int round = 0; round < 3; ++round) {
      const auto index = this->random_index(rng, store.size(), 120 + 20 * round);
      store.gather(index, grain);
      naive = this->naive_gather(naive, index);
      ASSERT_TRUE(this->matches(store, naive)) << "grain " << grain;
    }
  }
}

// After a gather exactly the maps of the survivors remain: a shared base map plus, per
// surviving ancestor, the distinct nodes of the paths it edited (computed from the slots).
TYPED_TEST(ParticleStoreTest, GatherFreesExactlyTheNodesNoSurvivorHolds) {
  constexpr std::size_t kParticles = 64;
  const std::uint64_t n = 5000;
  ParticleStore store(kParticles, this->heap_);
  LandmarkTree base(this->heap_);
  for (Slot s = 0; s < n; ++s) base.insert(tagged_landmark(0, s));
  const unsigned h = base.height();
  const std::int64_t base_nodes = dense_node_count<LandmarkTree>(n, h);
  ASSERT_EQ(this->heap_.stats().live_nodes, base_nodes);
  std::mt19937_64 rng(21);
  std::vector<std::vector<Slot>> touched(kParticles);
  for (std::size_t k = 0; k < kParticles; ++k) {
    store.map(k) = map_of(base, Indexing::kNone);
    for (int u = 0; u < 10; ++u) {
      const Slot s = static_cast<Slot>(rng() % n);
      touched[k].push_back(s);
      store.map(k).edit_unindexed(s).x = -1.0;
    }
  }
  // While the base handle lives, every base node does; each survivor adds its copied paths.
  auto expected_nodes = [&](const std::vector<std::size_t>& ancestors) {
    std::int64_t nodes = base_nodes;
    for (std::size_t a : ancestors) nodes += path_union<LandmarkTree>(touched[a], h).nodes;
    return nodes;
  };
  // Without the base handle, a base node lives while some survivor has not replaced it: the
  // survivors' copies plus the base nodes off at least one survivor's paths.
  auto expected_without_base = [&](const std::vector<std::size_t>& ancestors) {
    std::set<testing::NodeKey> in_every = testing::path_set<LandmarkTree>(touched[ancestors[0]], h);
    std::int64_t copies = 0;
    for (std::size_t a : ancestors) {
      const auto mine = testing::path_set<LandmarkTree>(touched[a], h);
      copies += static_cast<std::int64_t>(mine.size());
      std::set<testing::NodeKey> both;
      std::set_intersection(in_every.begin(), in_every.end(), mine.begin(), mine.end(),
                            std::inserter(both, both.end()));
      in_every = std::move(both);
    }
    return copies + base_nodes - static_cast<std::int64_t>(in_every.size());
  };
  std::vector<std::size_t> all(kParticles);
  for (std::size_t k = 0; k < kParticles; ++k) all[k] = k;
  ASSERT_EQ(this->heap_.stats().live_nodes, expected_nodes(all));
  // Ancestors 5, 9 and 40 survive (some several times); the others' paths are freed.
  std::vector<std::uint32_t> index(kParticles, 5);
  for (std::size_t k = 0; k < kParticles; k += 3) index[k] = 9;
  index[kParticles - 1] = 40;
  store.gather(index);
  EXPECT_EQ(this->heap_.stats().live_nodes, expected_nodes({5, 9, 40}));
  base.clear();  // base nodes every survivor replaced (its root at least) die with it
  EXPECT_EQ(this->heap_.stats().live_nodes, expected_without_base({5, 9, 40}));
  EXPECT_LT(expected_without_base({5, 9, 40}), expected_nodes({5, 9, 40}));
  store.gather(std::vector<std::uint32_t>(kParticles, 40));
  EXPECT_EQ(this->heap_.stats().live_nodes, expected_without_base({40}));
  EXPECT_EQ(this->heap_.stats().live_nodes, base_nodes);  // one whole map, nothing shared
}

TYPED_TEST(ParticleStoreTest, GatherRefusesAnOutOfRangeIndexAndChangesNothing) {
  ParticleStore store(5, this->heap_);
  std::vector<NaiveParticle> naive(5);
  std::mt19937_64 rng(4);
  for (std::size_t k = 0; k < 5; ++k) {
    this->set_columns(store, k, 0.25, naive[k]);
    this->mutate(store, k, naive[k], rng, 6);
  }
  std::vector<ParticleMap> maps;
  for (std::size_t k = 0; k < 5; ++k) maps.push_back(store.map(k));
  const std::int64_t allocations = this->heap_.stats().allocations;
  for (const auto& [index, message] :
       {std::pair{std::vector<std::uint32_t>{0, 1, 5, 2},
                  std::string("ParticleStore::gather: index[2] = 5 is not below the particle "
                              "count 5")},
        std::pair{std::vector<std::uint32_t>{4, 0xFFFF'FFFFu},
                  std::string("index[1] = 4294967295")}}) {
    try {
      store.gather(index);
      ADD_FAILURE() << "no throw";
    } catch (const std::invalid_argument& error) {
      EXPECT_NE(std::string(error.what()).find(message), std::string::npos) << error.what();
    }
    EXPECT_TRUE(this->matches(store, naive));
    for (std::size_t k = 0; k < 5; ++k) EXPECT_TRUE(store.map(k).shares_root_with(maps[k]));
  }
  EXPECT_EQ(this->heap_.stats().allocations, allocations);
}

// The covariance column: absent by default; carried, it moves with its particle (whatever the
// grain); as scratch, gather leaves its entries in place and only follows the particle count.
TYPED_TEST(ParticleStoreTest, PoseCovarianceColumnIsAbsentCarriedOrLeftInPlace) {
  constexpr std::size_t kStride = ParticleStore::kPoseCovStride;
  ParticleStore none(7, this->heap_);
  EXPECT_TRUE(none.pose_cov().empty());
  none.gather(std::vector<std::uint32_t>{1, 1, 2});
  EXPECT_TRUE(none.pose_cov().empty());

  auto fill = [](ParticleStore& store) {
    const std::span<double> cov = store.pose_cov();
    for (std::size_t i = 0; i < cov.size(); ++i) cov[i] = static_cast<double>(i) + 0.25;
  };
  std::mt19937_64 rng(13);
  for (std::size_t grain : {0u, 1u, 7u, 1000u}) {
    ParticleStore carried(40, this->heap_, {Indexing::kNone, PoseCovariance::kCarried});
    ASSERT_EQ(carried.pose_cov().size(), 40 * kStride);
    for (double c : carried.pose_cov()) ASSERT_EQ(c, 0.0);
    fill(carried);
    std::vector<double> before(carried.pose_cov().begin(), carried.pose_cov().end());
    for (std::size_t to : {40u, 55u, 12u}) {
      const auto index = this->random_index(rng, carried.size(), to);
      carried.gather(index, grain);
      ASSERT_EQ(carried.pose_cov().size(), to * kStride);
      for (std::size_t k = 0; k < to; ++k) {
        for (std::size_t e = 0; e < kStride; ++e) {
          ASSERT_EQ(carried.pose_cov()[k * kStride + e], before[index[k] * kStride + e])
              << "grain " << grain << ", particle " << k << ", entry " << e;
        }
      }
      before.assign(carried.pose_cov().begin(), carried.pose_cov().end());
    }
  }

  ParticleStore scratch(10, this->heap_, {Indexing::kNone, PoseCovariance::kScratch});
  fill(scratch);
  const std::vector<double> before(scratch.pose_cov().begin(), scratch.pose_cov().end());
  scratch.gather(std::vector<std::uint32_t>{9, 9, 9, 0, 1, 2, 3, 4, 5, 6});
  EXPECT_TRUE(std::equal(before.begin(), before.end(), scratch.pose_cov().begin(),
                         scratch.pose_cov().end()));
  scratch.gather(std::vector<std::uint32_t>{1, 2});
  EXPECT_EQ(scratch.pose_cov().size(), 2 * kStride);
}

// A store's maps take its indexing, and empty_map() gives one of the same kind.
TYPED_TEST(ParticleStoreTest, MapsTakeTheStoresIndexing) {
  ParticleStore plain(3, this->heap_);
  ParticleStore indexed(3, this->heap_, kIndexed);
  for (std::size_t k = 0; k < 3; ++k) {
    EXPECT_FALSE(plain.map(k).indexed());
    EXPECT_TRUE(indexed.map(k).indexed());
  }
  EXPECT_EQ(plain.empty_map().indexing(), Indexing::kNone);
  EXPECT_EQ(indexed.empty_map().indexing(), Indexing::kSpatial);
  indexed.map(1).insert(Landmark{.x = 3.0, .y = 4.0}, 1.0f);
  indexed.gather(std::vector<std::uint32_t>{1, 1, 0, 1});
  EXPECT_EQ(indexed.map(3).index().size(), 1u);
  EXPECT_TRUE(indexed.map(2).index().empty());
  EXPECT_TRUE(index_in_step(indexed.map(0)));
}

// Many rounds of a filter's memory traffic: every particle's map edited in parallel (distinct
// particles on distinct threads), then a gather inside a two-thread task_arena; the store
// matches the naive particles after every round.
TYPED_TEST(ParticleStoreTest, ParallelEditsAndGathersInATwoThreadArenaMatchTheOracle) {
  const std::size_t particles = sized<std::size_t>(256, 64);
  const int rounds = sized(40, 8);
  ParticleStore store(particles, this->heap_, kIndexed);
  std::vector<NaiveParticle> naive(particles);
  tbb::task_arena arena(2);
  std::mt19937_64 rng(77);
  for (int round = 0; round < rounds; ++round) {
    run_tasks(store.size(), 2, [&](std::size_t k) {
      std::mt19937_64 local(static_cast<std::uint64_t>(round) * 7919u + k);
      this->set_columns(store, k, static_cast<double>(round), naive[k]);
      this->mutate(store, k, naive[k], local, 1 + static_cast<int>(local() % 6));
    });
    const auto index = this->random_index(rng, store.size(), particles);
    arena.execute([&] { store.gather(index, 8); });
    naive = this->naive_gather(naive, index);
    ASSERT_TRUE(this->matches(store, naive)) << "round " << round;
  }
}

// Several stores whose maps share nodes (all start from one base map) edit and gather at once,
// each on its own thread (and each gather in parallel inside): reference counts of shared
// nodes move on many threads, and dead paths are freed by whichever thread drops them last.
TYPED_TEST(ParticleStoreTest, StoresSharingMapsGatherConcurrently) {
  constexpr std::size_t kStores = 4;
  const std::size_t particles = sized<std::size_t>(128, 32);
  const int rounds = sized(25, 6);
  LandmarkTree base(this->heap_);
  Oracle base_oracle;
  for (Slot s = 0; s < 300; ++s) {
    base.insert(tagged_landmark(1, s));
    base_oracle[s] = tagged_landmark(1, s);
  }
  std::vector<ParticleStore> stores;
  stores.reserve(kStores);
  std::vector<std::vector<NaiveParticle>> naive(kStores);
  for (std::size_t i = 0; i < kStores; ++i) {
    stores.emplace_back(particles, this->heap_, kIndexed);
    naive[i].resize(particles);
    const ParticleMap indexed_base = map_of(base, Indexing::kSpatial);
    for (std::size_t k = 0; k < particles; ++k) {
      stores[i].map(k) = indexed_base;
      naive[i][k].map = base_oracle;
    }
  }
  base.clear();
  // Under ThreadSanitizer (where gather forks plain std::threads) each store's gather stays on
  // its own thread: forks from several threads at once let a new thread adopt a dead thread's
  // recycled pthread id, and with it that thread's PoolHeap cache - ordered by glibc's stack
  // cache lock in reality, but TSan cannot see that lock and would report a race.
  const std::size_t grain = testing::kThreadSanitized ? particles : 16;
  std::vector<int> mismatches(kStores, 0);
  run_tasks(kStores, static_cast<int>(kStores), [&](std::size_t i) {
    std::mt19937_64 rng(1000 + i);
    tbb::task_arena arena(2);
    for (int round = 0; round < rounds; ++round) {
      for (std::size_t k = 0; k < stores[i].size(); ++k) {
        if (rng() % 4 == 0) this->mutate(stores[i], k, naive[i][k], rng, 3);
      }
      const auto index = this->random_index(rng, stores[i].size(), particles);
      arena.execute([&] { stores[i].gather(index, grain); });
      naive[i] = this->naive_gather(naive[i], index);
      if (!this->matches(stores[i], naive[i])) ++mismatches[i];
    }
  });
  for (std::size_t i = 0; i < kStores; ++i) {
    EXPECT_EQ(mismatches[i], 0) << "store " << i;
    EXPECT_TRUE(this->matches(stores[i], naive[i]));
  }
  stores.clear();
  EXPECT_EQ(this->heap_.stats().live_nodes, 0);
}

}  // namespace
}  // namespace fastslam::memory
