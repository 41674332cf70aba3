// Trees written and read back as one node graph against oracles: each tree's contents equal a
// std::map copy, the nodes read back equal the nodes written (live-node counts of the two
// heaps), roots shared before are shared after, and the bytes grow with the distinct nodes,
// not trees x landmarks. Malformed graphs (every truncation, every flipped byte, and named
// defects) are refused with TreeGraphError and leak nothing. LandmarkTree::diff is checked
// here too, against the difference of two std::maps.
#include "memory/tree_graph.h"

#include <cstdint>
#include <cstring>
#include <map>
#include <random>
#include <sstream>
#include <stdexcept>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "memory/landmark_tree.h"
#include "memory/node_heap.h"
#include "tests/memory/graph_records.h"
#include "tests/memory/heap_fixtures.h"

namespace fastslam::memory {
namespace {

using testing::Oracle;
using testing::same_contents;
using testing::sized;

Oracle oracle_of(const LandmarkTree& tree) {
  Oracle oracle;
  for (const auto [slot, landmark] : tree) oracle[slot] = landmark;
  return oracle;
}

// `count` trees as a particle set makes them: copies of earlier trees (resampling) changed by
// a few inserts, edits and erases (a scan), some far slots (holes), some left unchanged.
std::vector<LandmarkTree> particle_set(NodeHeap& heap, std::mt19937_64& rng, int count,
                                       int landmarks) {
  std::vector<LandmarkTree> trees;
  LandmarkTree first(heap);
  for (int k = 0; k < landmarks; ++k) first.insert(testing::random_landmark(rng, k));
  if (landmarks > 0) first.insert_at(5000 + static_cast<Slot>(rng() % 3000), testing::random_landmark(rng, 9));
  trees.push_back(first);
  for (int i = 1; i < count; ++i) {
    LandmarkTree tree = trees[rng() % trees.size()];
    const int changes = static_cast<int>(rng() % 4);
    for (int c = 0; c < changes; ++c) testing::random_scan_change(tree, rng, 1000 + i);
    trees.push_back(tree);
  }
  return trees;
}

std::string write_all(const std::vector<LandmarkTree>& trees) {
  std::ostringstream out;
  TreeGraphWriter writer(out);
  for (const LandmarkTree& tree : trees) writer.write(tree);
  EXPECT_TRUE(out.good());
  return out.str();
}

std::vector<LandmarkTree> read_all(const std::string& bytes, NodeHeap& heap, std::size_t count) {
  std::istringstream in(bytes);
  TreeGraphReader reader(in, heap);
  std::vector<LandmarkTree> trees;
  for (std::size_t i = 0; i < count; ++i) trees.push_back(reader.read([](Slot, const Landmark&) {}));
  reader.finish();
  return trees;
}

class TreeGraphTest : public testing::HeapLeakCheck<testing::Config<DefaultTreePolicy, PoolHeap>> {
 protected:
  PoolHeap other_heap_;
  void TearDown() override {
    HeapLeakCheck::TearDown();
    EXPECT_EQ(other_heap_.stats().live_nodes, 0) << "nodes leaked by the reader";
  }
};

TEST_F(TreeGraphTest, RoundTripKeepsContentsNodesAndSharing) {
  for (int trial = 0; trial < sized(20, 5); ++trial) {
    std::mt19937_64 rng(trial);
    const int count = 1 + static_cast<int>(rng() % 60);
    const int landmarks = static_cast<int>(rng() % 400);
    const std::vector<LandmarkTree> trees = particle_set(heap_, rng, count, landmarks);
    const std::string bytes = write_all(trees);
    const std::vector<LandmarkTree> back = read_all(bytes, other_heap_, trees.size());
    EXPECT_EQ(other_heap_.stats().live_nodes, heap_.stats().live_nodes) << "trial " << trial;
    EXPECT_EQ(other_heap_.stats().live_bytes, heap_.stats().live_bytes);
    for (std::size_t i = 0; i < trees.size(); ++i) {
      ASSERT_TRUE(same_contents(back[i], oracle_of(trees[i]))) << "trial " << trial << ", tree " << i;
      EXPECT_EQ(back[i].height(), trees[i].height());
      for (std::size_t j = 0; j < i; ++j) {
        EXPECT_EQ(back[i].shares_root_with(back[j]), trees[i].shares_root_with(trees[j]));
      }
    }
    // Written again, the copy gives the same bytes: the graph is a function of the sharing.
    EXPECT_EQ(write_all(back), bytes);
  }
}

TEST_F(TreeGraphTest, ReadTreesChangeLikeAnyOther) {
  std::mt19937_64 rng(5);
  const std::vector<LandmarkTree> trees = particle_set(heap_, rng, 8, 200);
  std::vector<LandmarkTree> back = read_all(write_all(trees), other_heap_, trees.size());
  std::vector<Oracle> oracles;
  for (const LandmarkTree& t : trees) oracles.push_back(oracle_of(t));
  for (int step = 0; step < 500; ++step) {
    const std::size_t i = rng() % back.size();
    const Landmark l = testing::random_landmark(rng, step);
    const Slot slot = back[i].insert(l);
    oracles[i][slot] = l;
    if (step % 3 == 0) {
      const Slot gone = oracles[i].begin()->first;
      back[i].erase(gone);
      oracles[i].erase(gone);
    }
  }
  for (std::size_t i = 0; i < back.size(); ++i) EXPECT_TRUE(same_contents(back[i], oracles[i]));
}

TEST_F(TreeGraphTest, BytesGrowWithDistinctNodesNotCopies) {
  std::mt19937_64 rng(9);
  LandmarkTree base(heap_);
  for (int k = 0; k < 5000; ++k) base.insert(testing::random_landmark(rng, k));
  const std::size_t one = write_all({base}).size();
  std::vector<LandmarkTree> copies(100, base);
  for (std::size_t i = 0; i < copies.size(); ++i) copies[i].edit(static_cast<Slot>(i * 37)).y = 1.0;
  const std::size_t hundred = write_all(copies).size();
  EXPECT_GT(one, 5000u * sizeof(Landmark));
  // Each copy adds its changed path (a leaf and its inner nodes), far below a map.
  EXPECT_LT(hundred, one + 100 * 1000) << "one map " << one << " bytes, 100 copies " << hundred;
}

TEST_F(TreeGraphTest, EmptyTreesAndTheCheckSeeEverySlot) {
  LandmarkTree empty(heap_);
  LandmarkTree holes(heap_);
  const std::vector<Slot> slots = {0, 3, 4, 700, 65536, 1u << 21};
  for (Slot s : slots) holes.insert_at(s, testing::tagged_landmark(3, s));
  const std::string bytes = write_all({empty, holes, empty});
  std::istringstream in(bytes);
  TreeGraphReader reader(in, other_heap_);
  std::vector<Slot> seen;
  const auto check = [&](Slot slot, const Landmark& l) {
    EXPECT_EQ(l, testing::tagged_landmark(3, slot));
    seen.push_back(slot);
  };
  EXPECT_TRUE(reader.read(check).empty());
  const LandmarkTree back = reader.read(check);
  EXPECT_TRUE(reader.read(check).empty());
  reader.finish();
  EXPECT_EQ(seen, slots);
  EXPECT_TRUE(same_contents(back, oracle_of(holes)));
}

TEST_F(TreeGraphTest, EveryTruncationIsRefusedAndLeaksNothing) {
  std::mt19937_64 rng(3);
  const std::vector<LandmarkTree> trees = particle_set(heap_, rng, 5, 40);
  const std::string bytes = write_all(trees);
  for (std::size_t n = 0; n < bytes.size(); ++n) {
    std::istringstream in(bytes.substr(0, n));
    TreeGraphReader reader(in, other_heap_);
    try {
      for (std::size_t i = 0; i < trees.size(); ++i) reader.read([](Slot, const Landmark&) {});
      FAIL() << "a graph cut at byte " << n << " of " << bytes.size() << " was read";
    } catch (const TreeGraphError&) {
      EXPECT_TRUE(reader.truncated()) << "cut at " << n;
    }
  }
}

TEST_F(TreeGraphTest, EveryFlippedByteIsRefusedOrReadsAValidGraph) {
  std::mt19937_64 rng(4);
  const std::vector<LandmarkTree> trees = particle_set(heap_, rng, 4, 30);
  const std::string bytes = write_all(trees);
  int refused = 0;
  for (std::size_t at = 0; at < bytes.size(); ++at) {
    std::string bad = bytes;
    bad[at] = static_cast<char>(bad[at] ^ (1 << (at % 8)));
    std::istringstream in(bad);
    try {
      TreeGraphReader reader(in, other_heap_);
      std::vector<LandmarkTree> back;
      for (std::size_t i = 0; i < trees.size(); ++i) {
        back.push_back(reader.read([](Slot, const Landmark&) {}));
      }
      reader.finish();
      // Accepted: a flip inside a landmark's bytes. Every tree is still well formed.
      for (const LandmarkTree& t : back) {
        std::size_t n = 0;
        for (auto it = t.begin(); it != t.end(); ++it) ++n;
        EXPECT_EQ(n, t.size());
      }
    } catch (const TreeGraphError&) {
      ++refused;
    }
  }
  EXPECT_GT(refused, 0);
}

using Graph = testing::GraphRecords;

TEST_F(TreeGraphTest, MalformedGraphsAreRefusedByName) {
  const std::vector<std::tuple<std::string, Graph, std::string>> cases = {
      {"unknown tag", Graph().raw(7), "unknown record tag 7"},
      {"empty leaf", Graph().leaf(0, 0), "occupancy is empty"},
      {"leaf mask beyond width", Graph().leaf(0, 1u << 4), "beyond its width"},
      {"leaf base not aligned", Graph().leaf(2, 1), "base slot is not a multiple"},
      {"inner of height 0", Graph().leaf(0, 1).inner(0, 0, 1, {0}), "inner node of height 0"},
      {"inner too high", Graph().leaf(0, 1).inner(9, 0, 1, {0}), "inner node of height 9"},
      {"child not earlier", Graph().leaf(0, 1).inner(1, 0, 1, {1}), "not an earlier node"},
      {"child at the wrong place", Graph().leaf(0, 1).inner(1, 0, 2, {0}),
       "not its place under the node"},
      {"child of the wrong height",
       Graph().leaf(0, 1).inner(1, 0, 1, {0}).inner(1, 0, 1, {1}),
       "not its place under the node"},
      {"inner without children", Graph().inner(1, 0, 0, {}), "none or beyond its width"},
      {"inner base not aligned", Graph().leaf(4, 1).inner(1, 4, 1, {0}),
       "not a multiple of its capacity"},
      {"root not earlier", Graph().tree(0, 0), "root is not an earlier node"},
      {"root with a base", Graph().leaf(4, 1).tree(0, 0), "not height 0 and base 0"},
      {"root of the wrong height", Graph().leaf(0, 1).tree(1, 0), "not height 1 and base 0"},
      {"empty tree with a height", Graph().tree(2, kNoNode), "an empty tree of height 2"},
  };
  for (const auto& [name, graph, message] : cases) {
    std::istringstream in(graph.bytes());
    TreeGraphReader reader(in, other_heap_);
    try {
      reader.read([](Slot, const Landmark&) {});
      ADD_FAILURE() << name << ": accepted";
    } catch (const TreeGraphError& e) {
      EXPECT_NE(std::string(e.what()).find(message), std::string::npos)
          << name << ": " << e.what();
      EXPECT_FALSE(reader.truncated()) << name;
    }
  }
}

TEST_F(TreeGraphTest, OrphansAndRefusedLandmarksLeakNothing) {
  {
    const Graph orphan = Graph().leaf(0, 1).leaf(4, 1).tree(0, 0);
    std::istringstream in(orphan.bytes());
    TreeGraphReader reader(in, other_heap_);
    const LandmarkTree tree = reader.read([](Slot, const Landmark&) {});
    EXPECT_EQ(tree.size(), 1u);
    EXPECT_THROW(reader.finish(), TreeGraphError);
  }
  {
    const Graph good = Graph().leaf(0, 3).leaf(4, 1).inner(1, 0, 3, {0, 1}).tree(1, 2);
    std::istringstream in(good.bytes());
    TreeGraphReader reader(in, other_heap_);
    EXPECT_THROW(reader.read([](Slot slot, const Landmark&) {
      if (slot == 4) throw std::runtime_error("refused");
    }),
                 std::runtime_error);
  }
}

// ---------------------------------------------------------------------------------------------
// LandmarkTree::diff

using Difference = std::vector<std::tuple<Slot, bool, bool>>;  // slot, in mine, in theirs

Difference oracle_diff(const Oracle& mine, const Oracle& theirs) {
  std::map<Slot, std::pair<bool, bool>> all;
  for (const auto& [slot, l] : mine) {
    const auto it = theirs.find(slot);
    if (it == theirs.end() || !(it->second == l)) all[slot].first = true;
  }
  for (const auto& [slot, l] : theirs) {
    const auto it = mine.find(slot);
    if (it == mine.end() || !(it->second == l)) all[slot].second = true;
  }
  Difference d;
  for (const auto& [slot, in] : all) {
    d.emplace_back(slot, in.first, in.second);
  }
  return d;
}

TEST_F(TreeGraphTest, DiffVisitsExactlyTheDifferingSlotsInOrder) {
  for (int trial = 0; trial < sized(40, 10); ++trial) {
    std::mt19937_64 rng(100 + trial);
    std::vector<LandmarkTree> trees = particle_set(heap_, rng, 12, static_cast<int>(rng() % 300));
    // Heights that differ: a far slot in one tree only.
    if (trial % 3 == 0) trees[1].insert_at(1u << 20, testing::tagged_landmark(2, 1u << 20));
    if (trial % 5 == 0) trees[2].clear();
    for (std::size_t i = 0; i < trees.size(); ++i) {
      for (std::size_t j = 0; j < trees.size(); ++j) {
        const Oracle mine = oracle_of(trees[i]);
        const Oracle theirs = oracle_of(trees[j]);
        Difference seen;
        trees[i].diff(trees[j], [&](Slot slot, const Landmark* a, const Landmark* b) {
          if (a != nullptr) {
            EXPECT_EQ(*a, mine.at(slot));
          }
          if (b != nullptr) {
            EXPECT_EQ(*b, theirs.at(slot));
          }
          // Both present: they differ, so both count as "changed".
          seen.emplace_back(slot, a != nullptr, b != nullptr);
        });
        EXPECT_EQ(seen, oracle_diff(mine, theirs)) << "trial " << trial << ", " << i << " vs " << j;
      }
    }
  }
}

}  // namespace
}  // namespace fastslam::memory
