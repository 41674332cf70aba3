// The persistent landmark tree against oracles: a std::map copied the naive way per particle
// (differential test), exact node counts computed from the slot bits (path copying, sharing,
// growth and collapse of the root), a failing heap (strong guarantee on contents, no leak), and
// bad use. Every generic suite runs over several tree shapes (binary up to 256-way) and both
// shipped heaps; every test ends with zero live nodes (HeapLeakCheck). The concurrent suites
// are in landmark_tree_concurrency_test.cc.
#include "memory/landmark_tree.h"

#include <algorithm>
#include <cstdint>
#include <map>
#include <random>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "memory/node_heap.h"
#include "tests/memory/heap_fixtures.h"

namespace fastslam::memory {
namespace {

using testing::capacity_at;
using testing::Config;
using testing::dense_node_count;
using testing::FailingHeap;
using testing::lowest_free;
using testing::minimal_height;
using testing::node_bytes;
using testing::NodeBytes;
using testing::Oracle;
using testing::path_union;
using testing::random_landmark;
using testing::same_contents;
using testing::sized;
using testing::tagged_landmark;

// Shapes: binary with one landmark per leaf, tiny fanouts (multi-level trees at small N), the
// default and its LocalRefcount twin (both instantiated in landmark_tree.cc), wider ones, and
// the widest allowed (256-way inner nodes, 32 landmarks per leaf: a full leaf mask is ~0u).
using Binary = TreePolicy<1, 0, LocalRefcount>;
using Tiny = TreePolicy<1, 1, AtomicRefcount>;
using I3L1 = TreePolicy<3, 1, LocalRefcount>;
using I4L2Local = TreePolicy<4, 2, LocalRefcount>;
using I5L2 = TreePolicy<5, 2, AtomicRefcount>;
using Widest = TreePolicy<8, 5, AtomicRefcount>;

using AllConfigs =
    ::testing::Types<Config<Binary, MallocHeap>, Config<Binary, PoolHeap>, Config<Tiny, MallocHeap>,
                     Config<Tiny, PoolHeap>, Config<I3L1, MallocHeap>, Config<I3L1, PoolHeap>,
                     Config<DefaultTreePolicy, MallocHeap>, Config<DefaultTreePolicy, PoolHeap>,
                     Config<I4L2Local, MallocHeap>, Config<I4L2Local, PoolHeap>,
                     Config<I5L2, MallocHeap>, Config<I5L2, PoolHeap>, Config<Widest, MallocHeap>,
                     Config<Widest, PoolHeap>>;

template <class C>
class LandmarkTreeTest : public testing::HeapLeakCheck<C> {
 protected:
  using TreeType = typename C::Tree;

  // A tree holding `n` tagged landmarks in slots [0, n), and its oracle.
  TreeType build(std::uint64_t n, Oracle& oracle, std::uint64_t tag = 1) {
    return build_on(this->heap_, n, oracle, tag);
  }
  static TreeType build_on(NodeHeap& heap, std::uint64_t n, Oracle& oracle, std::uint64_t tag = 1) {
    TreeType tree(heap);
    oracle.clear();
    for (Slot s = 0; s < n; ++s) {
      const Landmark l = tagged_landmark(tag, s);
      EXPECT_EQ(tree.insert(l), s);
      oracle[s] = l;
    }
    return tree;
  }
  std::int64_t live() const { return this->heap_.stats().live_nodes; }
  std::int64_t allocations() const { return this->heap_.stats().allocations; }
};

TYPED_TEST_SUITE(LandmarkTreeTest, AllConfigs, testing::ConfigName);

TYPED_TEST(LandmarkTreeTest, EmptyTreeHoldsNothingAndAllocatesNothing) {
  using Tree = typename TestFixture::TreeType;
  Tree tree(this->heap_);
  EXPECT_TRUE(tree.empty());
  EXPECT_EQ(tree.size(), 0u);
  EXPECT_EQ(tree.capacity(), 0u);
  EXPECT_EQ(tree.height(), 0u);
  EXPECT_EQ(&tree.heap(), &this->heap_);
  EXPECT_TRUE(tree.begin() == tree.end());
  EXPECT_EQ(tree.find(0), nullptr);
  EXPECT_FALSE(tree.contains(0));
  EXPECT_THROW(tree.at(0), std::out_of_range);
  Tree copy = tree;
  EXPECT_TRUE(copy.shares_root_with(tree));
  EXPECT_TRUE(same_contents(copy, Oracle{}));
  tree.clear();
  EXPECT_EQ(this->allocations(), 0);
}

TYPED_TEST(LandmarkTreeTest, InsertFillsSlotsInOrderAndGrowsOneLevelAtATime) {
  using Tree = typename TestFixture::TreeType;
  Tree tree(this->heap_);
  Oracle oracle;
  const std::uint64_t n = std::min<std::uint64_t>(capacity_at<Tree>(3) + 5, 5000);
  for (Slot s = 0; s < n; ++s) {
    const Landmark l = tagged_landmark(7, s);
    ASSERT_EQ(tree.insert(l), s);
    oracle[s] = l;
    ASSERT_EQ(tree.size(), s + 1u);
    ASSERT_EQ(tree.height(), minimal_height<Tree>(s + 1u)) << "after inserting slot " << s;
    ASSERT_EQ(tree.capacity(), capacity_at<Tree>(tree.height()));
    ASSERT_EQ(this->live(), dense_node_count<Tree>(s + 1u, tree.height()));
    ASSERT_EQ(tree.at(s), l);
  }
  EXPECT_TRUE(same_contents(tree, oracle));
}

TYPED_TEST(LandmarkTreeTest, EraseFromTheTopCollapsesTheRoot) {
  using Tree = typename TestFixture::TreeType;
  Oracle oracle;
  const std::uint64_t n = std::min<std::uint64_t>(capacity_at<Tree>(3) + 1, 3000);
  Tree tree = this->build(n, oracle);
  for (std::uint64_t left = n; left-- > 0;) {
    tree.erase(static_cast<Slot>(left));
    oracle.erase(static_cast<Slot>(left));
    ASSERT_EQ(tree.size(), left);
    if (left == 0) {
      ASSERT_EQ(tree.height(), 0u);
      ASSERT_EQ(tree.capacity(), 0u);
    } else {
      ASSERT_EQ(tree.height(), minimal_height<Tree>(left)) << left << " left";
    }
    ASSERT_EQ(this->live(), left == 0 ? 0 : dense_node_count<Tree>(left, tree.height()));
    if (left % 97 == 0) {
      ASSERT_TRUE(same_contents(tree, oracle));
    }
  }
  EXPECT_TRUE(tree.empty());
  EXPECT_EQ(this->live(), 0);
  // An emptied tree is an ordinary empty tree.
  EXPECT_EQ(tree.insert(tagged_landmark(1, 0)), 0u);
  EXPECT_EQ(tree.height(), 0u);
}

TYPED_TEST(LandmarkTreeTest, EraseFromTheBottomKeepsSlotsAndFreesEmptySubtrees) {
  using Tree = typename TestFixture::TreeType;
  Oracle oracle;
  const std::uint64_t n = std::min<std::uint64_t>(capacity_at<Tree>(2) + 3, 2000);
  Tree tree = this->build(n, oracle);
  const unsigned height = tree.height();
  for (Slot s = 0; s + 1 < n; ++s) {
    tree.erase(s);
    oracle.erase(s);
    // Slots keep their meaning; the height cannot shrink while the last slot is held.
    ASSERT_EQ(tree.height(), height);
    ASSERT_EQ(tree.at(static_cast<Slot>(n - 1)), oracle.at(static_cast<Slot>(n - 1)));
    // Nodes: the path of the last slot, plus the dense part [s + 1, n) of every level.
    std::int64_t expected = 0;
    for (unsigned j = 0; j <= height; ++j) {
      const std::uint64_t span = capacity_at<Tree>(j);
      expected += static_cast<std::int64_t>((n - 1) / span - (s + 1) / span + 1);
    }
    ASSERT_EQ(this->live(), expected) << "after erasing slot " << s;
  }
  EXPECT_TRUE(same_contents(tree, oracle));
}

TYPED_TEST(LandmarkTreeTest, InsertReusesTheLowestFreeSlot) {
  using Tree = typename TestFixture::TreeType;
  Oracle oracle;
  const std::uint64_t n = std::min<std::uint64_t>(4 * capacity_at<Tree>(1) + 3, 600);
  Tree tree = this->build(n, oracle);
  std::mt19937_64 rng(11);
  std::vector<Slot> erased;
  for (Slot s = 0; s < n; ++s) {
    if (rng() % 3 == 0) erased.push_back(s);
  }
  std::shuffle(erased.begin(), erased.end(), rng);
  for (Slot s : erased) {
    tree.erase(s);
    oracle.erase(s);
  }
  std::sort(erased.begin(), erased.end());
  for (Slot expected : erased) {
    ASSERT_EQ(lowest_free(oracle), expected);
    const Landmark l = tagged_landmark(2, expected);
    ASSERT_EQ(tree.insert(l), expected);
    oracle[expected] = l;
  }
  // Full again: the next slot is the end.
  EXPECT_EQ(tree.insert(tagged_landmark(2, static_cast<Slot>(n))), n);
  oracle[static_cast<Slot>(n)] = tagged_landmark(2, static_cast<Slot>(n));
  EXPECT_TRUE(same_contents(tree, oracle));
}

TYPED_TEST(LandmarkTreeTest, CopyIsConstantTimeAndEditsCopyExactlyThePath) {
  using Tree = typename TestFixture::TreeType;
  Oracle oracle;
  const std::uint64_t n = std::min<std::uint64_t>(capacity_at<Tree>(3) - 1, 1500);
  const Tree base = this->build(n, oracle);
  const unsigned h = base.height();
  const std::int64_t base_nodes = this->live();
  ASSERT_EQ(base_nodes, dense_node_count<Tree>(n, h));

  Tree copy = base;
  EXPECT_TRUE(copy.shares_root_with(base));
  EXPECT_EQ(this->live(), base_nodes);  // O(1): no node allocated

  std::mt19937_64 rng(5);
  std::vector<Slot> edited;
  Oracle copy_oracle = oracle;
  for (int i = 0; i < 12; ++i) {
    const Slot s = static_cast<Slot>(rng() % n);
    const std::int64_t before = this->allocations();
    const auto owned_before = path_union<Tree>(edited, h).nodes;
    edited.push_back(s);
    const auto owned_after = path_union<Tree>(edited, h).nodes;
    Landmark& l = copy.edit(s);
    l.x = -1.0 - i;
    copy_oracle[s].x = -1.0 - i;
    // Exactly the nodes of the path this map did not own yet.
    ASSERT_EQ(this->allocations() - before, owned_after - owned_before) << "edit of slot " << s;
    ASSERT_EQ(this->live(), base_nodes + owned_after);
  }
  EXPECT_FALSE(copy.shares_root_with(base));
  EXPECT_TRUE(same_contents(base, oracle));
  EXPECT_TRUE(same_contents(copy, copy_oracle));

  // Dropping the copy frees exactly the nodes it owned.
  copy.clear();
  EXPECT_EQ(this->live(), base_nodes);
}

TYPED_TEST(LandmarkTreeTest, UniquelyHeldTreeIsEditedInPlace) {
  using Tree = typename TestFixture::TreeType;
  Oracle oracle;
  Tree tree = this->build(std::min<std::uint64_t>(capacity_at<Tree>(2) + 7, 900), oracle);
  const std::int64_t before = this->allocations();
  for (const auto& [slot, landmark] : oracle) {
    const Landmark* address = tree.find(slot);
    Landmark& l = tree.edit(slot);
    ASSERT_EQ(&l, address);
    l.log_odds = 3.0;
    tree.set(slot, tree.at(slot));
  }
  EXPECT_EQ(this->allocations(), before);
  // A copy taken and dropped again leaves the tree uniquely held: still in place.
  { Tree copy = tree; }
  tree.edit(0).y = 1.0;
  EXPECT_EQ(this->allocations(), before);
  // Once a copy is alive, the same edit copies the path; the copy keeps the old value.
  Tree copy = tree;
  tree.edit(0).y = 2.0;
  EXPECT_EQ(this->allocations() - before, static_cast<std::int64_t>(tree.height()) + 1);
  EXPECT_EQ(copy.at(0).y, 1.0);
  EXPECT_EQ(tree.at(0).y, 2.0);
}

TYPED_TEST(LandmarkTreeTest, SharedSubtreesSurviveTheirFirstOwner) {
  using Tree = typename TestFixture::TreeType;
  Oracle oracle;
  const std::uint64_t n = std::min<std::uint64_t>(capacity_at<Tree>(2) + 1, 700);
  Tree first = this->build(n, oracle);
  Tree second = first;
  second.edit(static_cast<Slot>(n - 1)).x = 42.0;  // shares every subtree but one path
  Oracle second_oracle = oracle;
  second_oracle[static_cast<Slot>(n - 1)].x = 42.0;
  const std::int64_t second_nodes = dense_node_count<Tree>(n, second.height());
  first.clear();  // frees exactly first's root-to-leaf path of slot n - 1
  EXPECT_EQ(this->live(), second_nodes);
  EXPECT_TRUE(same_contents(second, second_oracle));
}

TYPED_TEST(LandmarkTreeTest, IteratesInSlotOrderOverSparseTrees) {
  using Tree = typename TestFixture::TreeType;
  Oracle oracle;
  const std::uint64_t n = std::min<std::uint64_t>(capacity_at<Tree>(3), 2500);
  Tree tree = this->build(n, oracle);
  std::mt19937_64 rng(3);
  // Leave runs, lone landmarks and whole empty subtrees.
  for (Slot s = 0; s < n; ++s) {
    const bool keep = (s / 37) % 3 == 0 || rng() % 11 == 0;
    if (!keep) {
      tree.erase(s);
      oracle.erase(s);
    }
  }
  EXPECT_TRUE(same_contents(tree, oracle));
  // Post-increment and iterator equality.
  auto it = tree.begin();
  auto expected = oracle.begin();
  while (it != tree.end()) {
    const auto before = it++;
    ASSERT_EQ((*before).slot, expected->first);
    ++expected;
    if (it != tree.end()) {
      ASSERT_EQ((*it).slot, expected->first);
    }
  }
  EXPECT_TRUE(expected == oracle.end());
  // Only the last slot held.
  for (auto e = oracle.begin(); e != oracle.end();) {
    if (std::next(e) == oracle.end()) break;
    tree.erase(e->first);
    e = oracle.erase(e);
  }
  ASSERT_EQ(tree.size(), 1u);
  EXPECT_EQ((*tree.begin()).slot, oracle.begin()->first);
  EXPECT_TRUE(std::next(tree.begin()) == tree.end());
}

TYPED_TEST(LandmarkTreeTest, MoveCopyAssignAndClear) {
  using Tree = typename TestFixture::TreeType;
  Oracle a_oracle;
  Oracle b_oracle;
  Tree a = this->build(50, a_oracle, 1);
  Tree b = this->build(9, b_oracle, 2);

  Tree moved(std::move(a));
  EXPECT_TRUE(a.empty());  // NOLINT(bugprone-use-after-move): moved-from is empty
  EXPECT_EQ(a.capacity(), 0u);
  EXPECT_TRUE(same_contents(moved, a_oracle));
  a = moved;  // a moved-from tree is assignable
  EXPECT_TRUE(a.shares_root_with(moved));

  b = b;  // self-assignment
  EXPECT_TRUE(same_contents(b, b_oracle));
  Tree& b_ref = b;
  b = std::move(b_ref);  // self move-assignment keeps the contents
  EXPECT_TRUE(same_contents(b, b_oracle));

  b = a;  // b's old nodes are freed, a's are shared
  EXPECT_TRUE(b.shares_root_with(a));
  EXPECT_TRUE(same_contents(b, a_oracle));
  a = b;  // assigning the very same root
  EXPECT_TRUE(same_contents(a, a_oracle));

  Tree c(this->heap_);
  c = std::move(b);
  EXPECT_TRUE(b.empty());  // NOLINT(bugprone-use-after-move)
  EXPECT_TRUE(same_contents(c, a_oracle));
  c.clear();
  EXPECT_TRUE(c.empty());
  EXPECT_EQ(c.height(), 0u);
  EXPECT_TRUE(c.begin() == c.end());
  EXPECT_EQ(c.insert(tagged_landmark(3, 0)), 0u);
  EXPECT_TRUE(same_contents(a, a_oracle));
  EXPECT_TRUE(same_contents(moved, a_oracle));
}

// Bad use: std::out_of_range naming the slot, nothing changed, nothing allocated, nothing
// copied (a shared tree stays shared).
TYPED_TEST(LandmarkTreeTest, BadSlotsAreRefusedClearlyAndChangeNothing) {
  using Tree = typename TestFixture::TreeType;
  Oracle oracle;
  const Tree base = this->build(40, oracle);
  Tree tree = base;
  tree.erase(7);
  tree.erase(39);
  Oracle tree_oracle = oracle;
  tree_oracle.erase(7);
  tree_oracle.erase(39);
  Tree shared = tree;
  const std::int64_t allocations = this->allocations();
  const std::vector<Slot> bad = {7,
                                 39,
                                 static_cast<Slot>(tree.capacity()),
                                 static_cast<Slot>(tree.capacity() + 1),
                                 1'000'000,
                                 0xFFFF'FFFFu};
  for (Slot slot : bad) {
    for (const char* op : {"at", "edit", "erase"}) {
      try {
        if (std::string(op) == "at") (void)shared.at(slot);
        if (std::string(op) == "edit") shared.edit(slot).x = 1.0;
        if (std::string(op) == "erase") shared.erase(slot);
        ADD_FAILURE() << op << "(" << slot << ") did not throw";
      } catch (const std::out_of_range& error) {
        const std::string what = error.what();
        EXPECT_NE(what.find("slot " + std::to_string(slot)), std::string::npos) << what;
        EXPECT_NE(what.find(op), std::string::npos) << what;
        const bool beyond = slot >= shared.capacity();
        EXPECT_NE(what.find(beyond ? "out of range" : "holds no landmark"), std::string::npos)
            << what;
      }
      EXPECT_EQ(shared.find(slot), nullptr);
    }
  }
  EXPECT_EQ(this->allocations(), allocations);
  EXPECT_TRUE(shared.shares_root_with(tree));
  EXPECT_TRUE(same_contents(shared, tree_oracle));
  EXPECT_TRUE(same_contents(tree, tree_oracle));
  EXPECT_TRUE(same_contents(base, oracle));

  Tree empty(this->heap_);
  EXPECT_THROW(empty.edit(0), std::out_of_range);
  EXPECT_THROW(empty.erase(0), std::out_of_range);
  EXPECT_EQ(empty.capacity(), 0u);
}

// The differential test: 100 particles, each a tree and a std::map copied the naive way; tens
// of thousands of random updates, inserts, erases, reads, copies and resampling gathers; every
// read equal, every time.
TYPED_TEST(LandmarkTreeTest, MatchesNaivelyCopiedStdMapUnderRandomOperations) {
  using Tree = typename TestFixture::TreeType;
  constexpr std::size_t kParticles = 100;
  const int steps = sized(40'000, 10'000);
  std::mt19937_64 rng(20240611u + Tree::kInnerBits * 8 + Tree::kLeafBits);
  std::vector<Tree> trees(kParticles, Tree(this->heap_));
  std::vector<Oracle> maps(kParticles);
  std::uint64_t next_id = 1;
  auto pick = [&](std::size_t n) { return static_cast<std::size_t>(rng() % n); };
  auto random_held = [&](const Oracle& m) {
    auto it = m.begin();
    std::advance(it, static_cast<std::ptrdiff_t>(pick(m.size())));
    return it->first;
  };
  std::size_t inserts = 0;
  std::size_t erases = 0;
  std::size_t edits = 0;
  std::size_t gathers = 0;

  for (int step = 0; step < steps; ++step) {
    // The target size swings between phases, so trees grow, empty out and grow again.
    static constexpr std::size_t kTargets[] = {120, 4, 300, 0, 60};
    const std::size_t target = kTargets[(step / 2500) % 5];
    const std::size_t k = pick(kParticles);
    Tree& tree = trees[k];
    Oracle& map = maps[k];
    const int insert_weight = map.size() < target ? 45 : 10;
    const int erase_weight = map.size() > target ? 45 : 10;
    int op = static_cast<int>(pick(100));
    if (op < 25) {  // update a held landmark (edit or set)
      if (map.empty()) continue;
      const Slot s = random_held(map);
      const Landmark l = random_landmark(rng, map[s].id);
      if (op % 2 == 0) {
        tree.edit(s) = l;
      } else {
        tree.set(s, l);
      }
      map[s] = l;
      ++edits;
    } else if ((op -= 25) < insert_weight) {  // insert: the lowest free slot
      const Landmark l = random_landmark(rng, next_id++);
      const Slot expected = lowest_free(map);
      const Slot s = tree.insert(l);
      ASSERT_EQ(s, expected) << "step " << step;
      map[s] = l;
      ++inserts;
    } else if ((op -= insert_weight) < erase_weight) {  // erase a held landmark
      if (map.empty()) continue;
      const Slot s = random_held(map);
      tree.erase(s);
      map.erase(s);
      ++erases;
    } else if (pick(50) == 0) {  // resampling: particle j becomes a copy of particle idx[j]
      const std::size_t ancestors = 1 + pick(12);
      std::vector<std::size_t> pool(ancestors);
      for (std::size_t& a : pool) a = pick(kParticles);
      std::vector<Tree> next_trees;
      std::vector<Oracle> next_maps;
      next_trees.reserve(kParticles);
      next_maps.reserve(kParticles);
      for (std::size_t j = 0; j < kParticles; ++j) {
        const std::size_t from = pool[pick(ancestors)];
        next_trees.push_back(trees[from]);
        next_maps.push_back(maps[from]);
      }
      trees = std::move(next_trees);
      maps = std::move(next_maps);
      ++gathers;
      for (std::size_t j = 0; j < kParticles; ++j) {
        ASSERT_TRUE(same_contents(trees[j], maps[j])) << "particle " << j << ", step " << step;
      }
      continue;
    } else if (pick(20) == 0) {  // one particle copies another
      const std::size_t from = pick(kParticles);
      tree = trees[from];
      map = maps[from];
    } else {  // reads only: held, free and far slots
      const Slot s = static_cast<Slot>(pick(map.empty() ? 8 : map.rbegin()->first + 9));
      const auto expected = map.find(s);
      const Landmark* found = tree.find(s);
      ASSERT_EQ(found != nullptr, expected != map.end()) << "slot " << s << ", step " << step;
      ASSERT_EQ(tree.contains(s), expected != map.end());
      if (expected == map.end()) {
        ASSERT_THROW((void)tree.at(s), std::out_of_range);
      } else {
        ASSERT_EQ(*found, expected->second);
        ASSERT_EQ(tree.at(s), expected->second);
      }
    }
    ASSERT_TRUE(same_contents(tree, map)) << "particle " << k << ", step " << step;
  }
  for (std::size_t j = 0; j < kParticles; ++j) {
    ASSERT_TRUE(same_contents(trees[j], maps[j])) << "particle " << j;
  }
  // The mix really exercised every operation.
  EXPECT_GT(inserts, static_cast<std::size_t>(steps) / 10);
  EXPECT_GT(erases, static_cast<std::size_t>(steps) / 10);
  EXPECT_GT(edits, static_cast<std::size_t>(steps) / 10);
  EXPECT_GT(gathers, 20u);
  trees.clear();
  EXPECT_EQ(this->live(), 0);
}

// Failure injection (immer's dada): for every k, the k-th allocation of an insert, edit or
// erase throws std::bad_alloc; on shared and unshared trees, around growth and collapse of the
// root. Afterwards the tree holds exactly the same landmarks (strong guarantee on contents),
// any tree sharing nodes with it too, the tree is still usable, and nothing leaks.
TYPED_TEST(LandmarkTreeTest, StrongGuaranteeOnContentsWhenAllocationFails) {
  using Tree = typename TestFixture::TreeType;
  enum class Op { kInsert, kEdit, kErase };
  FailingHeap failing(this->heap_);
  const std::uint64_t c1 = capacity_at<Tree>(1);
  const std::uint64_t c2 = capacity_at<Tree>(2);
  // Empty, one leaf, a full leaf, full trees (insert grows the root), one past full (erase
  // collapses it), a tree with holes (insert fills a hole).
  std::vector<std::uint64_t> sizes = {0, 1, Tree::kLeafWidth, c1, c1 + 1, 37};
  if (c2 <= 2048) {
    sizes.push_back(c2);
    sizes.push_back(c2 + 1);
  }
  int failures = 0;
  for (bool shared : {false, true}) {
    for (std::uint64_t n : sizes) {
      for (Op op : {Op::kInsert, Op::kEdit, Op::kErase}) {
        if (op != Op::kInsert && n == 0) continue;
        for (bool holes : {false, true}) {
          if (holes && n < 3) continue;
          for (std::int64_t k = 1;; ++k) {
            ASSERT_LT(k, 200) << "an operation that never stops allocating";
            Oracle oracle;
            Tree tree = TestFixture::build_on(failing, n, oracle);
            if (holes) {  // free slots 1 and n - 2 (insert then fills slot 1)
              for (Slot s : {Slot{1}, static_cast<Slot>(n - 2)}) {
                if (oracle.erase(s) == 1) tree.erase(s);
              }
            }
            const Tree base = shared ? tree : Tree(failing);
            const Oracle base_oracle = shared ? oracle : Oracle{};
            const Slot target = static_cast<Slot>(n - 1);  // held in every case but holes
            const Slot victim = oracle.empty() ? 0 : oracle.rbegin()->first;
            const Landmark fresh = tagged_landmark(99, static_cast<Slot>(k));
            auto apply = [&] {
              switch (op) {
                case Op::kInsert:
                  return tree.insert(fresh);
                case Op::kEdit:
                  tree.edit(victim).x = -7.0;
                  return target;
                case Op::kErase:
                  tree.erase(victim);
                  return target;
              }
              return target;
            };
            failing.fail_at(k);
            bool threw = false;
            Slot inserted = 0;
            try {
              inserted = apply();
            } catch (const std::bad_alloc&) {
              threw = true;
            }
            failing.disarm();
            if (threw) {
              ++failures;
              ASSERT_TRUE(same_contents(tree, oracle))
                  << "after bad_alloc at allocation " << k << " (n " << n << ", shared " << shared
                  << ", op " << static_cast<int>(op) << ")";
              ASSERT_TRUE(same_contents(base, base_oracle));
              inserted = apply();  // still usable: the same operation now succeeds
            }
            switch (op) {
              case Op::kInsert:
                ASSERT_EQ(inserted, lowest_free(oracle));
                oracle[inserted] = fresh;
                break;
              case Op::kEdit:
                oracle[victim].x = -7.0;
                break;
              case Op::kErase:
                oracle.erase(victim);
                break;
            }
            ASSERT_TRUE(same_contents(tree, oracle)) << "k " << k << ", n " << n;
            ASSERT_TRUE(same_contents(base, base_oracle));
            if (!threw) break;  // the operation needed fewer than k allocations
          }
          ASSERT_EQ(this->live(), 0) << "leak, n " << n << ", shared " << shared;
          ASSERT_EQ(failing.stats().live_nodes, 0);
        }
      }
    }
  }
  EXPECT_GT(failures, 50);
}

// insert_at, the loader's way to rebuild a map with holes: slots in any order, as far apart as
// 32 bits allow, give the oracle's contents on the minimal tree holding exactly their paths'
// nodes; insert then still takes the lowest free slot; a held slot is refused, naming it, and
// changes nothing.
TYPED_TEST(LandmarkTreeTest, InsertAtBuildsExactlyThePathsOfItsSlots) {
  using Tree = typename TestFixture::TreeType;
  std::mt19937_64 rng(21);
  for (int round = 0; round < 24; ++round) {
    Tree tree(this->heap_);
    Oracle oracle;
    std::vector<Slot> slots;
    for (int k = 0; k < 1 + 3 * round; ++k) {
      // same_contents probes every free slot below the last: at most 2^16 of them.
      const Slot s = static_cast<Slot>(rng() % (std::uint64_t{16} << (round % 13)));
      if (oracle.count(s) != 0) continue;
      const Landmark l = tagged_landmark(3, s);
      tree.insert_at(s, l);
      oracle[s] = l;
      slots.push_back(s);
      ASSERT_EQ(tree.size(), oracle.size());
      ASSERT_EQ(tree.height(), minimal_height<Tree>(std::uint64_t{oracle.rbegin()->first} + 1))
          << "after slot " << s;
      ASSERT_EQ(this->live(), path_union<Tree>(slots, tree.height()).nodes) << "after slot " << s;
    }
    ASSERT_TRUE(same_contents(tree, oracle));

    Tree shared = tree;
    const std::int64_t allocations = this->allocations();
    try {
      shared.insert_at(slots.back(), tagged_landmark(4, 0));
      ADD_FAILURE() << "insert_at(" << slots.back() << ") on a held slot did not throw";
    } catch (const std::invalid_argument& error) {
      EXPECT_NE(std::string(error.what()).find("slot " + std::to_string(slots.back())),
                std::string::npos)
          << error.what();
    }
    EXPECT_EQ(this->allocations(), allocations);
    EXPECT_TRUE(shared.shares_root_with(tree));

    const Landmark fresh = tagged_landmark(5, 0);
    const Slot expected = lowest_free(oracle);
    ASSERT_EQ(tree.insert(fresh), expected);
    oracle[expected] = fresh;
    ASSERT_TRUE(same_contents(tree, oracle));
    ASSERT_EQ(shared.size() + 1, tree.size());
  }
  // The last slot: the tallest tree, two paths, iterated in slot order.
  Tree far(this->heap_);
  for (Slot s : {0xFFFF'FFFFu, 3u}) far.insert_at(s, tagged_landmark(6, s));
  EXPECT_EQ(far.height(), minimal_height<Tree>(std::uint64_t{1} << 32));
  EXPECT_EQ(this->live(), path_union<Tree>({3u, 0xFFFF'FFFFu}, far.height()).nodes);
  EXPECT_EQ(far.at(0xFFFF'FFFFu), tagged_landmark(6, 0xFFFF'FFFFu));
  EXPECT_EQ(far.find(0xFFFF'FFFEu), nullptr);
  std::vector<Slot> order;
  for (const auto entry : far) order.push_back(entry.slot);
  EXPECT_EQ(order, (std::vector<Slot>{3u, 0xFFFF'FFFFu}));
}

// insert_at under failing allocations, on a tree held alone and on one shared: the contents
// and the height are as before, nothing leaks, and the same call then succeeds.
TYPED_TEST(LandmarkTreeTest, InsertAtKeepsTheContentsWhenAllocationFails) {
  using Tree = typename TestFixture::TreeType;
  FailingHeap failing(this->heap_);
  int failures = 0;
  for (bool shared : {false, true}) {
    for (std::int64_t k = 1;; ++k) {
      ASSERT_LT(k, 200) << "an insert_at that never stops allocating";
      Tree tree(failing);
      Oracle oracle;
      for (Slot s : {Slot{5}, Slot{1000}}) {
        tree.insert_at(s, tagged_landmark(1, s));
        oracle[s] = tagged_landmark(1, s);
      }
      const unsigned height = tree.height();
      const Tree base = shared ? tree : Tree(failing);
      const Oracle base_oracle = shared ? oracle : Oracle{};
      constexpr Slot kFar = 0x12345u;
      failing.fail_at(k);
      bool threw = false;
      try {
        tree.insert_at(kFar, tagged_landmark(2, kFar));
      } catch (const std::bad_alloc&) {
        threw = true;
      }
      failing.disarm();
      if (threw) {
        ++failures;
        ASSERT_TRUE(same_contents(tree, oracle)) << "after bad_alloc at allocation " << k;
        ASSERT_EQ(tree.height(), height) << "new roots left after bad_alloc at allocation " << k;
        tree.insert_at(kFar, tagged_landmark(2, kFar));
      }
      oracle[kFar] = tagged_landmark(2, kFar);
      ASSERT_TRUE(same_contents(tree, oracle));
      ASSERT_TRUE(same_contents(base, base_oracle));
      ASSERT_EQ(tree.height(), minimal_height<Tree>(std::uint64_t{kFar} + 1));
      if (!threw) break;
    }
    ASSERT_EQ(failing.stats().live_nodes, 0);
  }
  EXPECT_GT(failures, 2);
}

// ---------------------------------------------------------------------------------------------
// Non-generic tests

TEST(LandmarkTree, LandmarkIsSixtyFourTriviallyCopyableBytes) {
  static_assert(sizeof(Landmark) == 64);
  static_assert(std::is_trivially_copyable_v<Landmark>);
  static_assert(std::is_same_v<LandmarkTree, BasicLandmarkTree<DefaultTreePolicy>>);
  static_assert(LandmarkTree::kInnerWidth == 16 && LandmarkTree::kLeafWidth == 4);
  static_assert(std::is_nothrow_copy_constructible_v<LandmarkTree>);
  static_assert(std::is_nothrow_move_constructible_v<LandmarkTree>);
  static_assert(std::is_nothrow_move_assignable_v<LandmarkTree>);
}

TEST(LandmarkTree, ErrorMessagesNameTheSlotAndTheReason) {
  MallocHeap heap;
  LandmarkTree tree(heap);
  for (int i = 0; i < 10; ++i) tree.insert(Landmark{});
  tree.erase(4);
  try {
    tree.erase(4);
    FAIL() << "no throw";
  } catch (const std::out_of_range& error) {
    EXPECT_STREQ(error.what(),
                 "LandmarkTree::erase: slot 4 holds no landmark (never inserted, or erased)");
  }
  try {
    (void)tree.at(1234);
    FAIL() << "no throw";
  } catch (const std::out_of_range& error) {
    EXPECT_STREQ(error.what(), "LandmarkTree::at: slot 1234 is out of range (capacity 64)");
  }
}

// Scale: 100 particles share a 10^6-landmark map (10^5 under sanitizers); each updates 10
// random landmarks. The node count is exact: the base map's nodes plus, per particle, the
// distinct nodes on the union of its 10 root-to-leaf paths (computed here from the slots).
// Live bytes are within 1.2x of one map's landmarks plus the copied paths.
template <class Heap>
void check_scale() {
  using Tree = LandmarkTree;
  Heap heap;
  const std::uint64_t n = sized<std::uint64_t>(1'000'000, 100'000);
  constexpr std::size_t kParticles = 100;
  constexpr int kUpdates = 10;
  const NodeBytes sizes = node_bytes<Tree>();
  {
    Tree base(heap);
    for (std::uint64_t s = 0; s < n; ++s) base.insert(tagged_landmark(0, static_cast<Slot>(s)));
    const unsigned h = base.height();
    ASSERT_EQ(h, minimal_height<Tree>(n));
    const std::int64_t base_nodes = dense_node_count<Tree>(n, h);
    ASSERT_EQ(heap.stats().live_nodes, base_nodes);
    const std::int64_t base_bytes = heap.stats().live_bytes;

    std::mt19937_64 rng(99);
    std::vector<Tree> particles(kParticles, base);
    std::int64_t expected_nodes = base_nodes;
    std::int64_t expected_bytes = base_bytes;
    std::vector<std::vector<Slot>> touched(kParticles);
    for (std::size_t p = 0; p < kParticles; ++p) {
      for (int u = 0; u < kUpdates; ++u) {
        const Slot s = static_cast<Slot>(rng() % n);
        touched[p].push_back(s);
        particles[p].edit(s).x += 1.0;
      }
      const auto paths = path_union<Tree>(touched[p], h);
      expected_nodes += paths.nodes;
      expected_bytes += paths.inner * sizes.inner + paths.leaves * sizes.leaf;
    }
    const HeapStats stats = heap.stats();
    EXPECT_EQ(stats.live_nodes, expected_nodes);
    EXPECT_EQ(stats.live_bytes, expected_bytes);
    const double payload = static_cast<double>(n * sizeof(Landmark));
    const double copied = static_cast<double>(expected_bytes - base_bytes);
    EXPECT_LE(static_cast<double>(stats.live_bytes), 1.2 * (payload + copied));
    // Each particle reads its own updates and the base's landmarks elsewhere.
    for (std::size_t p = 0; p < kParticles; ++p) {
      for (Slot s : touched[p]) {
        const double times =
            static_cast<double>(std::count(touched[p].begin(), touched[p].end(), s));
        ASSERT_EQ(particles[p].at(s).x, static_cast<double>(s) + times);
      }
      const Slot other = static_cast<Slot>(rng() % n);
      if (std::count(touched[p].begin(), touched[p].end(), other) == 0) {
        ASSERT_EQ(particles[p].at(other), base.at(other));
      }
    }
    particles.clear();
    EXPECT_EQ(heap.stats().live_nodes, base_nodes);
  }
  EXPECT_EQ(heap.stats().live_nodes, 0);
  EXPECT_EQ(heap.stats().live_bytes, 0);
}

TEST(LandmarkTreeScale, HundredParticlesShareOneMillionLandmarksMalloc) {
  check_scale<MallocHeap>();
}
TEST(LandmarkTreeScale, HundredParticlesShareOneMillionLandmarksPool) { check_scale<PoolHeap>(); }

}  // namespace
}  // namespace fastslam::memory
