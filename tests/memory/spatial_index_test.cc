// The spatial index against brute force: every query (within, within_reach alone and in
// batches, in_footprint, nearest, for_each)
// over random maps (uniform, clustered, duplicates, points on cell boundaries, huge
// coordinates), through inserts, small and large moves and removals, after copies that each
// change differently (one oracle per handle), resampling-style gathers and growth of the root;
// strong guarantee under injected allocation failures; exact node counts of path copying; many
// threads copying, querying, moving and releasing shared indexes at once. Every test ends with
// zero live nodes. Labelled "concurrency": runs under ThreadSanitizer (smaller sizes).
#include "memory/spatial_index.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <random>
#include <set>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "memory/node_heap.h"
#include "parallel/particle_kernel.h"
#include "tests/memory/heap_fixtures.h"

namespace fastslam::memory {
namespace {

using testing::FailingHeap;
using testing::sized;

// ---------------------------------------------------------------------------------------------
// The oracle: the entries in a vector, every query by brute force.

using Oracle = std::vector<SpatialEntry>;

bool entry_less(const SpatialEntry& a, const SpatialEntry& b) {
  if (a.slot != b.slot) {
    return a.slot < b.slot;
  }
  if (a.x != b.x) {
    return a.x < b.x;
  }
  return a.y < b.y;
}

std::vector<SpatialEntry> sorted(std::vector<SpatialEntry> v) {
  std::sort(v.begin(), v.end(), entry_less);
  return v;
}

double d2(const SpatialEntry& e, double x, double y) {
  const double dx = e.x - x;
  const double dy = e.y - y;
  return dx * dx + dy * dy;
}

std::vector<SpatialEntry> brute_within(const Oracle& oracle, double x, double y, double r) {
  std::vector<SpatialEntry> out;
  for (const SpatialEntry& e : oracle) {
    if (d2(e, x, y) <= r * r) {
      out.push_back(e);
    }
  }
  return sorted(out);
}

// within_reach's oracle: within r, and within the entry's own reach a * extent + b.
std::vector<SpatialEntry> brute_within_reach(const Oracle& oracle, double x, double y, double r,
                                             double a, double b) {
  std::vector<SpatialEntry> out;
  for (const SpatialEntry& e : oracle) {
    const double dist2 = d2(e, x, y);
    if (dist2 <= r * r && !(dist2 > a * static_cast<double>(e.extent) + b)) {
      out.push_back(e);
    }
  }
  return sorted(out);
}

std::vector<SpatialEntry> brute_footprint(const Oracle& oracle, double x, double y, double heading,
                                          double range, double fov) {
  std::vector<SpatialEntry> out;
  for (const SpatialEntry& e : oracle) {
    if (d2(e, x, y) > range * range) {
      continue;
    }
    const double dx = e.x - x;
    const double dy = e.y - y;
    const bool at_sensor = dx == 0.0 && dy == 0.0;
    const double off = std::remainder(std::atan2(dy, dx) - heading, 2.0 * std::numbers::pi);
    if (at_sensor || fov >= 2.0 * std::numbers::pi || std::fabs(off) <= fov / 2) {
      out.push_back(e);
    }
  }
  return sorted(out);
}

// The query points and radii a check uses: near stored entries, and anywhere in the extent.
struct Query {
  double x;
  double y;
  double r;
};

template <class Index>
::testing::AssertionResult same_as_brute_force(const Index& index, const Oracle& oracle,
                                               std::mt19937_64& rng, int queries) {
  if (index.size() != oracle.size() || index.empty() != oracle.empty()) {
    return ::testing::AssertionFailure() << "size " << index.size() << ", oracle " << oracle.size();
  }
  std::vector<SpatialEntry> all;
  index.for_each([&](const SpatialEntry& e) { all.push_back(e); });
  if (sorted(all) != sorted(oracle)) {
    return ::testing::AssertionFailure() << "for_each differs from the oracle";
  }
  double lo_x = 0.0;
  double hi_x = 1.0;
  double lo_y = 0.0;
  double hi_y = 1.0;
  if (!oracle.empty()) {
    lo_x = hi_x = oracle[0].x;
    lo_y = hi_y = oracle[0].y;
    for (const SpatialEntry& e : oracle) {
      lo_x = std::min(lo_x, e.x);
      hi_x = std::max(hi_x, e.x);
      lo_y = std::min(lo_y, e.y);
      hi_y = std::max(hi_y, e.y);
    }
  }
  const double extent = std::max({hi_x - lo_x, hi_y - lo_y, 1.0});
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  const double radii[] = {0.0, 1e-3, 0.5, 3.0, 20.0, 0.05 * extent, 0.3 * extent, 3.0 * extent};
  for (int q = 0; q < queries; ++q) {
    Query query;
    if (!oracle.empty() && q % 2 == 0) {
      const SpatialEntry& e = oracle[rng() % oracle.size()];
      const double jitter = (q % 4 == 0) ? 0.0 : radii[rng() % 6];
      query = {e.x + jitter * (unit(rng) - 0.5), e.y + jitter * (unit(rng) - 0.5), 0.0};
    } else {
      query = {lo_x - 0.1 * extent + 1.2 * extent * unit(rng),
               lo_y - 0.1 * extent + 1.2 * extent * unit(rng), 0.0};
    }
    query.r = radii[rng() % std::size(radii)] * (q % 3 == 0 ? 1.0 : unit(rng));
    std::vector<SpatialEntry> got;
    index.within(query.x, query.y, query.r, [&](const SpatialEntry& e) { got.push_back(e); });
    if (sorted(got) != brute_within(oracle, query.x, query.y, query.r)) {
      return ::testing::AssertionFailure()
             << "within(" << query.x << ", " << query.y << ", " << query.r << "): " << got.size()
             << " entries, brute force " << brute_within(oracle, query.x, query.y, query.r).size();
    }
    // From a subtree: the box covered is the disc's own square (exactly: the disc touches the
    // node's boundary), padded, or some other box (then the query must fall back to the root);
    // the same entries in the same order as from the root.
    {
      const double pads[] = {0.0, 1e-9, 0.5, 0.2 * extent};
      const double pad = pads[rng() % std::size(pads)];
      double bx = query.x;
      double by = query.y;
      if (q % 5 == 1) {  // a box elsewhere
        bx = lo_x + extent * unit(rng);
        by = lo_y + extent * unit(rng);
      }
      const double half = (q % 7 == 3) ? 0.0 : query.r + pad;
      const auto from = index.covering(bx - half, by - half, bx + half, by + half);
      // (The root's square always holds [-16, 16)^2.)
      if (!oracle.empty() && from.empty() && std::max(std::fabs(bx), std::fabs(by)) + half < 1.0) {
        return ::testing::AssertionFailure() << "covering a box near the origin is empty";
      }
      std::vector<SpatialEntry> from_root;
      index.within(query.x, query.y, query.r,
                   [&](const SpatialEntry& e) { from_root.push_back(e); });
      std::vector<SpatialEntry> from_node;
      index.within(from, query.x, query.y, query.r,
                   [&](const SpatialEntry& e) { from_node.push_back(e); });
      if (from_node != from_root) {
        return ::testing::AssertionFailure()
               << "within(subtree of side " << from.side() << ", " << query.x << ", " << query.y
               << ", " << query.r << "): " << from_node.size() << " entries, from the root "
               << from_root.size() << " (or in another order)";
      }
      // Each entry's own reach a * extent + b (extents 0 .. ~2000): from none to all of the
      // disc, from this subtree and from the root (an empty subtree).
      const double r2 = query.r * query.r;
      const double scales[] = {0.0, 1e-4, 1e-3, 1.0};
      const double a = r2 * scales[rng() % std::size(scales)] * unit(rng);
      const double b = (q % 3 == 1) ? 0.0 : r2 * 0.2 * unit(rng);
      const auto reach2 = [a, b](float e) { return a * static_cast<double>(e) + b; };
      const std::vector<SpatialEntry> expected =
          brute_within_reach(oracle, query.x, query.y, query.r, a, b);
      for (const auto& start : {from, typename Index::Subtree()}) {
        std::vector<SpatialEntry> reached;
        index.within_reach(start, query.x, query.y, query.r, reach2,
                           [&](const SpatialEntry& e) { reached.push_back(e); });
        if (sorted(reached) != expected) {
          return ::testing::AssertionFailure()
                 << "within_reach(subtree of side " << start.side() << ", " << query.x << ", "
                 << query.y << ", " << query.r << ", " << a << " * extent + " << b
                 << "): " << reached.size() << " entries, brute force " << expected.size();
        }
      }
      // A batch: this disc and others around it (some far, some beyond the subtree), up to 70
      // (two groups of 64), each with its own reach; every disc's hits as its own query's.
      if (q % 4 == 2) {
        using Disc = typename Index::Disc;
        const std::size_t count = (q % 16 == 2) ? 70 : rng() % 9;
        std::vector<Disc> discs;
        std::vector<std::pair<double, double>> reach;
        for (std::size_t k = 0; k < count; ++k) {
          const double spread = (k % 5 == 4) ? 3.0 * extent : 2.0 * half + 1.0;
          const double radius = radii[rng() % std::size(radii)] * unit(rng);
          discs.push_back(
              {query.x + spread * (unit(rng) - 0.5), query.y + spread * (unit(rng) - 0.5), radius});
          const double rk2 = radius * radius;
          reach.emplace_back(rk2 * scales[rng() % std::size(scales)] * unit(rng),
                             (k % 3 == 1) ? 0.0 : rk2 * 0.2 * unit(rng));
        }
        for (const auto& start : {from, typename Index::Subtree()}) {
          std::vector<std::vector<SpatialEntry>> hits(count);
          index.within_reach(
              start, std::span<const Disc>(discs),
              [&](std::size_t k, float e) {
                return reach[k].first * static_cast<double>(e) + reach[k].second;
              },
              [&](std::size_t k, const SpatialEntry& e) { hits.at(k).push_back(e); });
          for (std::size_t k = 0; k < count; ++k) {
            const std::vector<SpatialEntry> want = brute_within_reach(
                oracle, discs[k].x, discs[k].y, discs[k].radius, reach[k].first, reach[k].second);
            if (sorted(hits[k]) != want) {
              return ::testing::AssertionFailure()
                     << "batch within_reach, disc " << k << " of " << count << " (" << discs[k].x
                     << ", " << discs[k].y << ", " << discs[k].radius << "): " << hits[k].size()
                     << " entries, brute force " << want.size();
            }
          }
        }
      }
    }
    const double heading = (unit(rng) - 0.5) * 4.0 * std::numbers::pi;
    const double fov = (q % 5 == 0) ? 2.0 * std::numbers::pi : unit(rng) * 1.5 * std::numbers::pi;
    got.clear();
    index.in_footprint(query.x, query.y, heading, query.r, fov,
                       [&](const SpatialEntry& e) { got.push_back(e); });
    if (sorted(got) != brute_footprint(oracle, query.x, query.y, heading, query.r, fov)) {
      return ::testing::AssertionFailure() << "in_footprint(" << query.x << ", " << query.y << ", "
                                           << heading << ", " << query.r << ", " << fov << ")";
    }
    const std::size_t k = std::size_t{1} + rng() % 12;
    std::vector<SpatialEntry> near(k + 2);
    const std::size_t n = index.nearest(query.x, query.y, k, near);
    std::vector<double> expected;
    for (const SpatialEntry& e : oracle) {
      expected.push_back(d2(e, query.x, query.y));
    }
    std::sort(expected.begin(), expected.end());
    expected.resize(std::min(k, expected.size()));
    if (n != expected.size()) {
      return ::testing::AssertionFailure()
             << "nearest returns " << n << ", expected " << expected.size();
    }
    for (std::size_t i = 0; i < n; ++i) {
      if (d2(near[i], query.x, query.y) != expected[i] ||
          std::find(oracle.begin(), oracle.end(), near[i]) == oracle.end()) {
        return ::testing::AssertionFailure() << "nearest: rank " << i << " of " << n;
      }
    }
  }
  return ::testing::AssertionSuccess();
}

// ---------------------------------------------------------------------------------------------
// Maps and changes

enum class Kind { kUniform, kClustered, kDuplicates, kGrid, kHuge };

const char* kind_name(Kind kind) {
  switch (kind) {
    case Kind::kUniform:
      return "uniform";
    case Kind::kClustered:
      return "clustered";
    case Kind::kDuplicates:
      return "duplicates";
    case Kind::kGrid:
      return "grid";
    case Kind::kHuge:
      return "huge";
  }
  return "?";
}

// A point of the given kind of map.
std::pair<double, double> random_point(Kind kind, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  switch (kind) {
    case Kind::kUniform:
      return {-500.0 + 1000.0 * unit(rng), -500.0 + 1000.0 * unit(rng)};
    case Kind::kClustered: {
      // Eight tight clusters (sigma 2 cm .. 2 m) around fixed centres.
      const int c = static_cast<int>(rng() % 8);
      std::normal_distribution<double> spread(0.0, 0.02 * std::pow(2.0, c));
      return {100.0 * c + spread(rng), -37.5 * c + spread(rng)};
    }
    case Kind::kDuplicates: {
      // A few exact positions, many entries each (leaves at the finest size grow).
      static constexpr double kSpots[][2] = {{0.0, 0.0}, {1.5, -2.25}, {1.5, -2.2500001}, {-3, 7}};
      const auto& spot = kSpots[rng() % 4];
      return {spot[0], spot[1]};
    }
    case Kind::kGrid: {
      // Integer and half-integer points, many on power-of-two cell boundaries.
      const double step = (rng() % 2 == 0) ? 16.0 : 0.5;
      return {step * static_cast<double>(static_cast<int>(rng() % 41) - 20),
              step * static_cast<double>(static_cast<int>(rng() % 41) - 20)};
    }
    case Kind::kHuge: {
      const double scale = std::pow(10.0, static_cast<double>(rng() % 15) * 10.0);  // 1 .. 1e140
      return {scale * (unit(rng) - 0.5), scale * (unit(rng) - 0.5)};
    }
  }
  return {0.0, 0.0};
}

// One random change of `index`, mirrored in `oracle`: insert, erase, or a move (small, by
// metres, or anywhere).
template <class Index>
void random_change(Index& index, Oracle& oracle, Kind kind, Slot& next_slot, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const unsigned op = static_cast<unsigned>(rng() % 10);
  if (oracle.empty() || op < 3) {
    const auto [x, y] = random_point(kind, rng);
    const auto extent = static_cast<float>(rng() % 1000);
    index.insert(next_slot, x, y, extent);
    oracle.push_back({next_slot++, extent, x, y});
    return;
  }
  const std::size_t i = rng() % oracle.size();
  SpatialEntry& e = oracle[i];
  if (op < 5) {
    index.erase(e.slot, e.x, e.y);
    e = oracle.back();
    oracle.pop_back();
    return;
  }
  double x;
  double y;
  if (op < 7) {
    x = e.x + 0.05 * unit(rng);  // an EKF update
    y = e.y + 0.05 * unit(rng);
  } else if (op < 9) {
    x = e.x + 8.0 * unit(rng);  // a loop closure
    y = e.y + 8.0 * unit(rng);
  } else {
    std::tie(x, y) = random_point(kind, rng);
  }
  // An EKF update shrinks the landmark's covariance; some grow, so that a leaf's widest entry
  // also changes upwards (the index must not assume either).
  const float extent = e.slot % 4 == 0 ? 2.0f * e.extent + 1.0f : 0.5f * e.extent;
  index.move(e.slot, e.x, e.y, x, y, extent);
  e.x = x;
  e.y = y;
  e.extent = extent;
}

// ---------------------------------------------------------------------------------------------
// Suites over shapes (4- and 16-way, leaves of 8 and 16, atomic and plain counts) and heaps.

template <class P, class H>
struct Config {
  using Index = BasicSpatialIndex<P>;
  using Heap = H;
};

template <class C>
class SpatialIndexTest : public ::testing::Test {
 protected:
  using IndexType = typename C::Index;
  void TearDown() override {
    const HeapStats stats = heap_.stats();
    EXPECT_EQ(stats.live_nodes, 0) << "nodes leaked";
    EXPECT_EQ(stats.live_bytes, 0) << "bytes leaked";
  }
  typename C::Heap heap_;
};

using Configs = ::testing::Types<Config<DefaultSpatialPolicy, PoolHeap>,
                                 Config<SpatialPolicy<1, 8, LocalRefcount>, MallocHeap>,
                                 Config<SpatialPolicy<2, 16, AtomicRefcount>, MallocHeap>,
                                 Config<SpatialPolicy<2, 8, AtomicRefcount>, PoolHeap>>;
TYPED_TEST_SUITE(SpatialIndexTest, Configs);

TYPED_TEST(SpatialIndexTest, EmptyIndexFindsNothing) {
  typename TestFixture::IndexType index(this->heap_);
  int visited = 0;
  index.within(0.0, 0.0, 1e9, [&](const SpatialEntry&) { ++visited; });
  index.in_footprint(0.0, 0.0, 0.0, 1e9, 1.0, [&](const SpatialEntry&) { ++visited; });
  std::vector<SpatialEntry> out(3);
  EXPECT_EQ(index.nearest(0.0, 0.0, 3, out), 0u);
  EXPECT_EQ(visited, 0);
  EXPECT_THROW(index.erase(0, 0.0, 0.0), std::out_of_range);
  EXPECT_THROW(index.move(0, 0.0, 0.0, 1.0, 1.0), std::out_of_range);
  EXPECT_EQ(index.depth(), 0u);
}

TYPED_TEST(SpatialIndexTest, RandomMapsMatchBruteForce) {
  for (Kind kind :
       {Kind::kUniform, Kind::kClustered, Kind::kDuplicates, Kind::kGrid, Kind::kHuge}) {
    SCOPED_TRACE(kind_name(kind));
    std::mt19937_64 rng(1234 + static_cast<int>(kind));
    typename TestFixture::IndexType index(this->heap_);
    Oracle oracle;
    Slot next = 0;
    const int n = sized(1500, 300);
    for (int i = 0; i < n; ++i) {
      const auto [x, y] = random_point(kind, rng);
      index.insert(next, x, y);
      oracle.push_back({next++, 0.0f, x, y});
    }
    ASSERT_TRUE(same_as_brute_force(index, oracle, rng, sized(120, 30)));
    for (int round = 0; round < 6; ++round) {
      for (int i = 0; i < n / 2; ++i) {
        random_change(index, oracle, kind, next, rng);
      }
      ASSERT_TRUE(same_as_brute_force(index, oracle, rng, sized(60, 15))) << "round " << round;
    }
    // Remove everything: the index is empty again and frees every node.
    while (!oracle.empty()) {
      const SpatialEntry e = oracle.back();
      oracle.pop_back();
      index.erase(e.slot, e.x, e.y);
    }
    EXPECT_TRUE(same_as_brute_force(index, oracle, rng, 3));
    EXPECT_EQ(this->heap_.stats().live_nodes, 0);
  }
}

TYPED_TEST(SpatialIndexTest, GridQueriesExactlyOnTheRadius) {
  // Integer points and integer radii: squared distances are exact, so "distance <= radius"
  // has no rounding slack to hide behind; the points lie on every power-of-two cell boundary.
  typename TestFixture::IndexType index(this->heap_);
  Oracle oracle;
  Slot slot = 0;
  for (int x = -40; x <= 40; ++x) {
    for (int y = -40; y <= 40; y += 1) {
      index.insert(slot, x, y);
      oracle.push_back({slot++, 0.0f, static_cast<double>(x), static_cast<double>(y)});
    }
  }
  for (double qx : {0.0, 16.0, -32.0, 7.0, 8.0}) {
    for (double qy : {0.0, 16.0, -8.0, 5.0}) {
      for (double r : {0.0, 1.0, 5.0, 8.0, 13.0, 16.0, 25.0}) {
        std::vector<SpatialEntry> got;
        index.within(qx, qy, r, [&](const SpatialEntry& e) { got.push_back(e); });
        ASSERT_EQ(sorted(got), brute_within(oracle, qx, qy, r)) << qx << " " << qy << " " << r;
        // From the node covering the disc's square exactly (its boundary through grid points).
        std::vector<SpatialEntry> from_node;
        index.within(index.covering(qx - r, qy - r, qx + r, qy + r), qx, qy, r,
                     [&](const SpatialEntry& e) { from_node.push_back(e); });
        ASSERT_EQ(from_node, got) << qx << " " << qy << " " << r;
        got.clear();
        index.in_footprint(qx, qy, std::numbers::pi / 2, r, std::numbers::pi / 2,
                           [&](const SpatialEntry& e) { got.push_back(e); });
        ASSERT_EQ(sorted(got),
                  brute_footprint(oracle, qx, qy, std::numbers::pi / 2, r, std::numbers::pi / 2));
      }
    }
  }
}

// within_reach with NaN extents (reaching everywhere, as !(d2 > NaN)) and extents that rise and
// fall in place: every entry of the disc whose reach covers the point, none other.
TYPED_TEST(SpatialIndexTest, WithinReachFollowsExtentsInPlace) {
  typename TestFixture::IndexType index(this->heap_);
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  struct Item {
    Slot slot;
    float extent;
    double x;
    double y;
  };
  std::vector<Item> items;
  for (Slot s = 0; s < 400; ++s) {
    items.push_back({s, static_cast<float>(unit(rng)), 200.0 * unit(rng), 200.0 * unit(rng)});
    index.insert(s, items.back().x, items.back().y, items.back().extent);
  }
  const auto reach2 = [](float e) { return 400.0 * static_cast<double>(e); };  // 20 m at 1
  for (int round = 0; round < 60; ++round) {
    // Change extents in place (small moves stay in their leaves): up, down, to NaN and back.
    for (int k = 0; k < 40; ++k) {
      Item& it = items[rng() % items.size()];
      const unsigned op = static_cast<unsigned>(rng() % 5);
      const float extent = op == 0   ? std::numeric_limits<float>::quiet_NaN()
                           : op == 1 ? 25.0f * static_cast<float>(unit(rng))
                                     : 0.01f * static_cast<float>(unit(rng));
      const double x = it.x + 1e-3 * (unit(rng) - 0.5);
      index.move(it.slot, it.x, it.y, x, it.y, extent);
      it.x = x;
      it.extent = extent;
    }
    const double qx = 200.0 * unit(rng);
    const double qy = 200.0 * unit(rng);
    const double r = 80.0 * unit(rng);
    std::set<Slot> expected;
    for (const Item& it : items) {
      const double dx = it.x - qx;
      const double dy = it.y - qy;
      const double dist2 = dx * dx + dy * dy;
      if (dist2 <= r * r && !(dist2 > reach2(it.extent))) expected.insert(it.slot);
    }
    std::set<Slot> got;
    const auto from = index.covering(qx - r, qy - r, qx + r, qy + r);
    index.within_reach(from, qx, qy, r, reach2, [&](const SpatialEntry& e) {
      EXPECT_TRUE(got.insert(e.slot).second) << "visited twice: " << e.slot;
    });
    ASSERT_EQ(got, expected) << "round " << round;
  }
}

TYPED_TEST(SpatialIndexTest, CoveringDescendsToTheSmallestSquare) {
  // 4096 points on a 1 m grid over [0, 64)^2: a box inside one 8 m cell of the grid is covered
  // by a node of side at most 8 m; a box across the origin only by the root; an empty index or
  // a box outside the root's square gives an empty subtree, and queries from it still answer.
  typename TestFixture::IndexType index(this->heap_);
  EXPECT_TRUE(index.covering(0.0, 0.0, 1.0, 1.0).empty());
  Slot slot = 0;
  for (int x = 0; x < 64; ++x) {
    for (int y = 0; y < 64; ++y) {
      index.insert(slot++, x + 0.25, y + 0.25);
    }
  }
  const auto small = index.covering(17.0, 41.0, 23.5, 47.5);
  ASSERT_FALSE(small.empty());
  EXPECT_LE(small.side(), 8.0);
  EXPECT_GE(small.side(), 0.5);
  const auto across = index.covering(-1.0, -1.0, 1.0, 1.0);
  ASSERT_FALSE(across.empty());
  EXPECT_GE(across.side(), 128.0);
  EXPECT_TRUE(index.covering(-1e300, 0.0, 0.0, 1.0).empty());
  Oracle oracle;
  index.for_each([&](const SpatialEntry& e) { oracle.push_back(e); });
  for (const auto& from : {small, across, decltype(small){}}) {
    // A disc inside `small`, and one outside it (answered from the root).
    for (const auto& [qx, qy] : {std::pair{20.0, 44.0}, std::pair{60.0, 5.0}}) {
      std::vector<SpatialEntry> got;
      index.within(from, qx, qy, 2.0, [&](const SpatialEntry& e) { got.push_back(e); });
      EXPECT_EQ(got.size(), 13u) << from.side();
      EXPECT_EQ(sorted(got), brute_within(oracle, qx, qy, 2.0)) << from.side();
    }
  }
  index.clear();
}

TYPED_TEST(SpatialIndexTest, RootGrowsAndShrinks) {
  typename TestFixture::IndexType index(this->heap_);
  Oracle oracle;
  std::mt19937_64 rng(7);
  Slot slot = 0;
  for (double scale = 1.0; scale < 1e149; scale *= 37.0) {
    for (const auto& [sx, sy] : {std::pair{1.0, 1.0}, {-1.0, 0.5}, {0.25, -1.0}, {-1.0, -1.0}}) {
      index.insert(slot, sx * scale, sy * scale);
      oracle.push_back({slot++, 0.0f, sx * scale, sy * scale});
    }
    ASSERT_TRUE(same_as_brute_force(index, oracle, rng, 10)) << scale;
  }
  const unsigned grown = index.depth();
  // Keep only the small points: merges and root hand-overs bring the depth back down.
  while (std::fabs(oracle.back().x) > 100.0) {
    index.erase(oracle.back().slot, oracle.back().x, oracle.back().y);
    oracle.pop_back();
  }
  EXPECT_TRUE(same_as_brute_force(index, oracle, rng, 20));
  EXPECT_LT(index.depth(), grown);
  EXPECT_LE(index.depth(), 3u);
  // Coordinates beyond kMaxCoordinate, or not finite, are refused and change nothing.
  const double bad[] = {std::numeric_limits<double>::quiet_NaN(),
                        std::numeric_limits<double>::infinity(), -1e151};
  for (double b : bad) {
    EXPECT_THROW(index.insert(99, b, 0.0), std::invalid_argument);
    EXPECT_THROW(index.insert(99, 0.0, b), std::invalid_argument);
    EXPECT_THROW(index.move(oracle[0].slot, oracle[0].x, oracle[0].y, b, 1.0),
                 std::invalid_argument);
  }
  EXPECT_THROW(index.erase(oracle[0].slot, oracle[0].x + 1e-9, oracle[0].y), std::out_of_range);
  EXPECT_THROW(index.erase(oracle[0].slot + 1000, oracle[0].x, oracle[0].y), std::out_of_range);
  EXPECT_THROW(index.move(oracle[0].slot, oracle[0].x, 1e6, 0.0, 0.0), std::out_of_range);
  EXPECT_TRUE(same_as_brute_force(index, oracle, rng, 20));
}

TYPED_TEST(SpatialIndexTest, CopiesChangeIndependently) {
  using Index = typename TestFixture::IndexType;
  std::mt19937_64 rng(99);
  for (Kind kind : {Kind::kUniform, Kind::kClustered, Kind::kDuplicates}) {
    SCOPED_TRACE(kind_name(kind));
    Index base(this->heap_);
    Oracle base_oracle;
    Slot next = 0;
    for (int i = 0; i < sized(800, 200); ++i) {
      random_change(base, base_oracle, kind, next, rng);
    }
    const std::int64_t base_nodes = this->heap_.stats().live_nodes;
    std::vector<Index> copies(12, base);
    std::vector<Oracle> oracles(copies.size(), base_oracle);
    EXPECT_EQ(this->heap_.stats().live_nodes, base_nodes);  // copies are O(1)
    for (std::size_t c = 0; c < copies.size(); ++c) {
      EXPECT_TRUE(copies[c].shares_root_with(base));
      Slot slots = next;
      for (std::size_t i = 0; i < 10 * c + 1; ++i) {
        random_change(copies[c], oracles[c], kind, slots, rng);
      }
    }
    for (std::size_t c = 0; c < copies.size(); ++c) {
      ASSERT_TRUE(same_as_brute_force(copies[c], oracles[c], rng, sized(30, 8))) << "copy " << c;
    }
    ASSERT_TRUE(same_as_brute_force(base, base_oracle, rng, sized(30, 8)));
    copies.clear();
    EXPECT_EQ(this->heap_.stats().live_nodes, base_nodes);
  }
}

TYPED_TEST(SpatialIndexTest, ResamplingGathers) {
  using Index = typename TestFixture::IndexType;
  std::mt19937_64 rng(5);
  const std::size_t particles = sized(24, 8);
  std::vector<Index> indexes(particles, Index(this->heap_));
  std::vector<Oracle> oracles(particles);
  std::vector<Slot> next(particles, 0);
  for (int step = 0; step < sized(40, 12); ++step) {
    for (std::size_t p = 0; p < particles; ++p) {
      for (int i = 0; i < 15; ++i) {
        random_change(indexes[p], oracles[p], Kind::kClustered, next[p], rng);
      }
    }
    // A gather by random ancestors, as resampling does (some particles copied many times).
    std::vector<std::size_t> ancestor(particles);
    for (std::size_t& a : ancestor) {
      a = rng() % (particles / 3 + 1);
    }
    std::vector<Index> gathered;
    std::vector<Oracle> gathered_oracles;
    std::vector<Slot> gathered_next;
    for (std::size_t a : ancestor) {
      gathered.push_back(indexes[a]);
      gathered_oracles.push_back(oracles[a]);
      gathered_next.push_back(next[a]);
    }
    indexes = std::move(gathered);
    oracles = std::move(gathered_oracles);
    next = std::move(gathered_next);
    if (step % 8 == 7) {
      for (std::size_t p = 0; p < particles; ++p) {
        ASSERT_TRUE(same_as_brute_force(indexes[p], oracles[p], rng, 6)) << step << " " << p;
      }
    }
  }
}

// MoveFinger: runs of moves of entries near each other (small, leaving their leaves, or far),
// with copies of the index made and changed between the moves (the finger's path becomes
// shared and must be owned again), as plain moves: the index against the oracle after every
// run, the copies and the base unchanged by them; and under injected allocation failures, the
// moves before the failing one done, the failing one not.
TYPED_TEST(SpatialIndexTest, MoveFingerRunsMatchPlainMoves) {
  using Index = typename TestFixture::IndexType;
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (Kind kind : {Kind::kUniform, Kind::kClustered, Kind::kDuplicates, Kind::kGrid}) {
    SCOPED_TRACE(kind_name(kind));
    Index base(this->heap_);
    Oracle base_oracle;
    Slot next = 0;
    for (int i = 0; i < sized(1500, 300); ++i) {
      random_change(base, base_oracle, kind, next, rng);
    }
    Index index = base;
    Oracle oracle = base_oracle;
    for (int run = 0; run < sized(60, 15); ++run) {
      // The entries nearest a random one, in random order.
      const SpatialEntry centre = oracle[rng() % oracle.size()];
      std::vector<std::size_t> near(oracle.size());
      for (std::size_t i = 0; i < near.size(); ++i) near[i] = i;
      std::sort(near.begin(), near.end(), [&](std::size_t a, std::size_t b) {
        return d2(oracle[a], centre.x, centre.y) < d2(oracle[b], centre.x, centre.y);
      });
      near.resize(std::min<std::size_t>(near.size(), 1 + rng() % 12));
      std::shuffle(near.begin(), near.end(), rng);
      std::vector<Index> copies;
      std::vector<Oracle> copy_oracles;
      typename Index::MoveFinger finger(index);
      for (std::size_t i : near) {
        SpatialEntry& e = oracle[i];
        const unsigned op = static_cast<unsigned>(rng() % 10);
        double x = e.x + 0.01 * unit(rng);  // an EKF update
        double y = e.y + 0.01 * unit(rng);
        if (op == 7 || op == 8) {
          x = e.x + 8.0 * unit(rng);
          y = e.y + 8.0 * unit(rng);
        } else if (op == 9) {
          std::tie(x, y) = random_point(kind, rng);
        }
        const float extent = e.slot % 3 == 0 ? 2.0f * e.extent + 1.0f : 0.5f * e.extent;
        finger.move(e.slot, e.x, e.y, x, y, extent);
        e = {e.slot, extent, x, y};
        if (rng() % 4 == 0) {
          copies.push_back(index);  // shares the finger's path
          copy_oracles.push_back(oracle);
          if (rng() % 2 == 0) {  // and changes it: the path's children become shared
            Slot copy_next = next + 1000000;
            random_change(copies.back(), copy_oracles.back(), kind, copy_next, rng);
          }
        }
      }
      ASSERT_TRUE(same_as_brute_force(index, oracle, rng, 3)) << "run " << run;
      for (std::size_t c = 0; c < copies.size(); ++c) {
        ASSERT_TRUE(same_as_brute_force(copies[c], copy_oracles[c], rng, 2)) << run << " " << c;
      }
    }
    ASSERT_TRUE(same_as_brute_force(base, base_oracle, rng, 4));
  }
  // Allocation failures: a run on a copy (every path shared), failed at its k-th allocation.
  FailingHeap failing(this->heap_);
  for (std::int64_t k = 1;; ++k) {
    Index shared(failing);
    Oracle oracle;
    Slot next = 0;
    for (int i = 0; i < 400; ++i) {
      random_change(shared, oracle, Kind::kClustered, next, rng);
    }
    const Oracle before = oracle;
    Index index = shared;
    typename Index::MoveFinger finger(index);
    failing.fail_at(k);
    bool threw = false;
    try {
      for (std::size_t i = 0; i < 8; ++i) {
        SpatialEntry& e = oracle[(i * 37) % oracle.size()];
        const double x = e.x + (i % 3 == 2 ? 5.0 : 0.001);
        finger.move(e.slot, e.x, e.y, x, e.y, e.extent);
        e.x = x;
      }
    } catch (const std::bad_alloc&) {
      threw = true;
    }
    failing.disarm();
    ASSERT_TRUE(same_as_brute_force(index, oracle, rng, 3)) << "failed at " << k;
    ASSERT_TRUE(same_as_brute_force(shared, before, rng, 2)) << "failed at " << k;
    if (!threw) {
      EXPECT_GT(k, 1);
      break;
    }
  }
}

TYPED_TEST(SpatialIndexTest, StrongGuaranteeOnAllocationFailure) {
  using Index = typename TestFixture::IndexType;
  FailingHeap failing(this->heap_);
  std::mt19937_64 rng(11);
  // Each case: a fresh index (shared with a base copy, so changes must copy paths) and one
  // operation; the operation is failed at its 1st, 2nd, ... allocation until it succeeds.
  for (int variant = 0; variant < 8; ++variant) {
    int failed = 0;
    for (std::int64_t k = 1;; ++k) {
      Index base(failing);
      Oracle oracle;
      Slot next = 0;
      for (int i = 0; i < 300; ++i) {
        random_change(base, oracle, variant % 2 == 0 ? Kind::kUniform : Kind::kClustered, next,
                      rng);
      }
      Index index = base;
      if (variant >= 4) {
        index = Index(failing);  // unshared: in-place changes, splits and merges
        for (const SpatialEntry& e : oracle) {
          index.insert(e.slot, e.x, e.y, e.extent);
        }
      }
      const SpatialEntry target = oracle[rng() % oracle.size()];
      const auto [px, py] = random_point(Kind::kUniform, rng);
      failing.fail_at(k);
      bool threw = false;
      try {
        switch (variant % 4) {
          case 0:
            index.insert(next, target.x + 1e-6, target.y);
            break;  // likely splits
          case 1:
            index.erase(target.slot, target.x, target.y);
            break;
          case 2:
            index.move(target.slot, target.x, target.y, px, py);
            break;
          default:
            index.move(target.slot, target.x, target.y, target.x + 1e-7, target.y);
        }
      } catch (const std::bad_alloc&) {
        threw = true;
      }
      failing.disarm();
      if (threw) {
        ASSERT_TRUE(same_as_brute_force(index, oracle, rng, 4)) << variant << " at " << k;
      }
      ASSERT_TRUE(same_as_brute_force(base, oracle, rng, 2)) << variant << " at " << k;
      if (!threw) {
        break;
      }
      ++failed;
    }
    if (variant < 4) {
      EXPECT_GT(failed, 0) << "variant " << variant << ": a shared change must allocate";
    }
  }
  // Erasing down to a merge, failing every allocation: erase never fails once it owns its
  // path (a merge that cannot allocate is skipped), and the index stays exact.
  Index index(failing);
  Oracle oracle;
  Slot next = 0;
  for (int i = 0; i < 200; ++i) {
    random_change(index, oracle, Kind::kClustered, next, rng);
  }
  failing.fail_at(1);
  while (!oracle.empty()) {
    const SpatialEntry e = oracle.back();
    oracle.pop_back();
    index.erase(e.slot, e.x, e.y);  // owned path: no allocation but the merge's
    failing.fail_at(1);
  }
  failing.disarm();
  EXPECT_TRUE(same_as_brute_force(index, oracle, rng, 2));
}

// ---------------------------------------------------------------------------------------------
// Node counts of path copying (default shape)

TEST(SpatialIndexNodes, HundredCopiesTenMovesEach) {
  PoolHeap heap;
  std::mt19937_64 rng(3);
  SpatialIndex base(heap);
  Oracle oracle;
  const int n = sized(50000, 5000);
  const double side = std::sqrt(static_cast<double>(n)) * 10.0;
  std::uniform_real_distribution<double> u(0.0, side);
  for (int i = 0; i < n; ++i) {
    const double x = u(rng);
    const double y = u(rng);
    base.insert(static_cast<Slot>(i), x, y);
    oracle.push_back({static_cast<Slot>(i), 0.0f, x, y});
  }
  const std::int64_t base_nodes = heap.stats().live_nodes;
  std::vector<SpatialIndex> handles(100, base);
  std::int64_t expected = base_nodes;
  for (SpatialIndex& handle : handles) {
    // Ten moves inside their leaves' squares: each copies the nodes of its path that this
    // handle does not own yet, so the handle owns exactly the union of the ten paths.
    std::set<const void*> paths;
    for (int m = 0; m < 10; ++m) {
      const SpatialEntry& e = oracle[rng() % oracle.size()];
      base.for_each_path_node(e.x, e.y, [&](const void* node) { paths.insert(node); });
      handle.move(e.slot, e.x, e.y, e.x, e.y);  // same position: an in-place write
    }
    expected += static_cast<std::int64_t>(paths.size());
  }
  EXPECT_EQ(heap.stats().live_nodes, expected);
  // The union of ten paths is at most ten paths long; the root is always among them.
  EXPECT_LE(expected - base_nodes, 100 * 10 * static_cast<std::int64_t>(base.depth()));
  handles.clear();
  EXPECT_EQ(heap.stats().live_nodes, base_nodes);
  // Moves by metres leave their leaves: new nodes are bounded by the two paths plus a split.
  std::vector<SpatialIndex> movers(20, base);
  Oracle moved = oracle;
  for (SpatialIndex& handle : movers) {
    const std::int64_t before = heap.stats().live_nodes;
    SpatialEntry& e = moved[rng() % moved.size()];
    const double to_x = std::clamp(e.x + 5.0, 0.0, side - 1.0);
    handle.move(e.slot, e.x, e.y, to_x, e.y);
    const std::int64_t grown = heap.stats().live_nodes - before;
    EXPECT_LE(grown, 2 * static_cast<std::int64_t>(base.depth()) + 4 + 4);
  }
  movers.clear();
  EXPECT_EQ(heap.stats().live_nodes, base_nodes);
  base = SpatialIndex(heap);
  EXPECT_EQ(heap.stats().live_nodes, 0);
}

// ---------------------------------------------------------------------------------------------
// Concurrency: particles copying, querying, changing and releasing shared indexes at once.

TEST(SpatialIndexConcurrency, ParticlesShareCopyChangeAndRelease) {
  PoolHeap heap;
  parallel::ParticleKernel kernel({.threads = 4, .grain = 1});
  const std::size_t particles = sized<std::size_t>(48, 16);
  const int steps = sized(12, 4);
  std::mt19937_64 seed_rng(21);
  // A few shared bases.
  std::vector<SpatialIndex> indexes;
  std::vector<Oracle> oracles;
  for (std::size_t b = 0; b < 4; ++b) {
    SpatialIndex base(heap);
    Oracle oracle;
    Slot next = 0;
    for (int i = 0; i < sized(600, 150); ++i) {
      random_change(base, oracle, Kind::kClustered, next, seed_rng);
    }
    indexes.push_back(base);
    oracles.push_back(oracle);
  }
  std::atomic<int> failures{0};
  for (int step = 0; step < steps; ++step) {
    // Gather: particle p descends from index p * 7 % size (many particles share one).
    std::vector<SpatialIndex> next_indexes(particles, SpatialIndex(heap));
    std::vector<Oracle> next_oracles(particles);
    kernel.for_each_particle(particles, [&](std::size_t p) {
      const std::size_t parent = (p * 7 + static_cast<std::size_t>(step)) % indexes.size();
      SpatialIndex mine = indexes[parent];  // concurrent copies of shared roots
      Oracle oracle = oracles[parent];
      std::mt19937_64 rng(static_cast<std::uint64_t>(step) * 1000003 + p);
      Slot next = 1u << 20 | static_cast<Slot>(p << 10 | static_cast<std::size_t>(step) << 16);
      for (int i = 0; i < 20; ++i) {
        random_change(mine, oracle, Kind::kClustered, next, rng);
      }
      // Read the parent (shared, being copied by others) and the own copy.
      if (!same_as_brute_force(mine, oracle, rng, 3) ||
          !same_as_brute_force(indexes[parent], oracles[parent], rng, 1)) {
        failures.fetch_add(1);
      }
      next_indexes[p] = std::move(mine);
      next_oracles[p] = std::move(oracle);
    });
    // Release the old generation from many threads at once.
    kernel.for_each_particle(indexes.size(),
                             [&](std::size_t p) { indexes[p] = SpatialIndex(heap); });
    indexes = std::move(next_indexes);
    oracles = std::move(next_oracles);
  }
  EXPECT_EQ(failures.load(), 0);
  kernel.for_each_particle(indexes.size(), [&](std::size_t p) { indexes[p].clear(); });
  EXPECT_EQ(heap.stats().live_nodes, 0);
}

}  // namespace
}  // namespace fastslam::memory
