// The persistent landmark tree under concurrency: many tasks at once copy shared maps, edit,
// insert and erase in their copies (path copying on nodes other threads hold), check the
// contents against an oracle, hand their maps to the next round (so nodes are freed by threads
// other than their allocators) and release them; readers iterate a shared map while writers
// edit copies of it; the last references to shared nodes are dropped by many threads at once.
// Runs over the atomic-refcount shapes and both heaps; every test ends with zero live nodes.
// Labelled "concurrency": runs under ThreadSanitizer too (plain std::threads there, smaller
// sizes; see heap_fixtures.h).
#include <atomic>
#include <cstdint>
#include <mutex>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "memory/landmark_tree.h"
#include "memory/node_heap.h"
#include "tests/memory/heap_fixtures.h"

namespace fastslam::memory {
namespace {

using testing::Config;
using testing::lowest_free;
using testing::Oracle;
using testing::run_tasks;
using testing::same_contents;
using testing::sized;
using testing::tagged_landmark;

using AtomicConfigs =
    ::testing::Types<Config<DefaultTreePolicy, MallocHeap>, Config<DefaultTreePolicy, PoolHeap>,
                     Config<TreePolicy<1, 0, AtomicRefcount>, PoolHeap>,
                     Config<TreePolicy<1, 1, AtomicRefcount>, MallocHeap>,
                     Config<TreePolicy<3, 1, AtomicRefcount>, PoolHeap>>;

// Collects failures seen on worker threads; checked on the main thread afterwards.
class Failures {
 public:
  void add(const std::string& what) {
    if (count_.fetch_add(1) == 0) {
      std::lock_guard lock(mutex_);
      first_ = what;
    }
  }
  int count() const { return count_.load(); }
  std::string first() const {
    std::lock_guard lock(mutex_);
    return first_;
  }

 private:
  std::atomic<int> count_{0};
  mutable std::mutex mutex_;
  std::string first_;
};

template <class C>
class LandmarkTreeConcurrencyTest : public testing::HeapLeakCheck<C> {
 protected:
  using TreeType = typename C::Tree;

  // Base map `i`: tagged landmarks in [0, n_i), with every seventh slot from 3 erased.
  TreeType make_base(std::size_t i, Oracle& oracle) {
    TreeType tree(this->heap_);
    const Slot n = static_cast<Slot>(40 + 29 * i);
    for (Slot s = 0; s < n; ++s) oracle[tree.insert(tagged_landmark(i, s))] = tagged_landmark(i, s);
    for (Slot s = 3; s < n; s += 7) {
      tree.erase(s);
      oracle.erase(s);
    }
    return tree;
  }

  // A few random edits, inserts and erases on `tree`, mirrored in `oracle`.
  static void mutate(TreeType& tree, Oracle& oracle, std::mt19937_64& rng, int ops,
                     std::uint64_t tag, Failures& failures) {
    for (int op = 0; op < ops; ++op) {
      const int kind = static_cast<int>(rng() % 3);
      if (kind == 0 || (kind == 2 && oracle.size() < 8)) {
        const Slot expected = lowest_free(oracle);
        const Landmark l = tagged_landmark(tag, expected);
        const Slot s = tree.insert(l);
        if (s != expected) failures.add("insert returned slot " + std::to_string(s));
        oracle[s] = l;
      } else if (!oracle.empty()) {
        auto it = oracle.begin();
        std::advance(it, static_cast<std::ptrdiff_t>(rng() % oracle.size()));
        const Slot s = it->first;
        if (kind == 1) {
          Landmark& l = tree.edit(s);
          l.x += 1.0;
          l.last_seen = static_cast<std::int64_t>(tag);
          it->second.x += 1.0;
          it->second.last_seen = static_cast<std::int64_t>(tag);
        } else {
          tree.erase(s);
          oracle.erase(it);
        }
      }
    }
  }
};

TYPED_TEST_SUITE(LandmarkTreeConcurrencyTest, AtomicConfigs, testing::ConfigName);

// A pool of shared maps; each round, many tasks copy one (from the pool or from the previous
// round's results, whose nodes other threads allocated), edit/insert/erase, check the contents,
// copy again and drop the second copy, and leave the result for the next round. The previous
// round's results are then released by many tasks at once.
TYPED_TEST(LandmarkTreeConcurrencyTest, TasksCopyEditVerifyAndReleaseSharedMaps) {
  using Tree = typename TestFixture::TreeType;
  constexpr std::size_t kPool = 8;
  const std::size_t tasks = sized<std::size_t>(512, 64);
  const int rounds = sized(30, 6);
  std::vector<Tree> pool;
  std::vector<Oracle> pool_oracles(kPool);
  for (std::size_t i = 0; i < kPool; ++i) pool.push_back(this->make_base(i, pool_oracles[i]));
  const std::int64_t pool_nodes = this->heap_.stats().live_nodes;

  std::vector<Tree> previous;
  std::vector<Oracle> previous_oracles;
  Failures failures;
  for (int round = 0; round < rounds; ++round) {
    std::vector<Tree> next(tasks, Tree(this->heap_));
    std::vector<Oracle> next_oracles(tasks);
    run_tasks(tasks, 4, [&](std::size_t i) {
      std::mt19937_64 rng(static_cast<std::uint64_t>(round) * 1'000'003u + i);
      const bool from_previous = !previous.empty() && rng() % 2 == 0;
      const std::size_t source = from_previous ? rng() % previous.size() : rng() % kPool;
      const Tree& shared = from_previous ? previous[source] : pool[source];
      const Oracle& shared_oracle = from_previous ? previous_oracles[source] : pool_oracles[source];
      Tree tree = shared;  // O(1), bumps the root's count
      Oracle oracle = shared_oracle;
      TestFixture::mutate(tree, oracle, rng, 1 + static_cast<int>(rng() % 24), i, failures);
      if (!same_contents(tree, oracle))
        failures.add("copy of a shared map, task " + std::to_string(i));
      if (!same_contents(shared, shared_oracle)) failures.add("the shared source changed");
      {
        Tree second = tree;
        Oracle second_oracle = oracle;
        TestFixture::mutate(second, second_oracle, rng, 3, i + 7, failures);
        if (!same_contents(second, second_oracle)) failures.add("second copy");
      }  // dropped: frees only what `second` owned alone
      if (!same_contents(tree, oracle)) failures.add("after the second copy died");
      next[i] = std::move(tree);
      next_oracles[i] = std::move(oracle);
    });
    ASSERT_EQ(failures.count(), 0) << failures.first() << " (round " << round << ")";
    // The previous round's maps die, many at once; nodes they share with `next` survive.
    run_tasks(previous.size(), 4, [&](std::size_t i) { previous[i].clear(); });
    for (std::size_t i = 0; i < tasks; ++i) {
      ASSERT_TRUE(same_contents(next[i], next_oracles[i])) << "round " << round << ", map " << i;
    }
    previous = std::move(next);
    previous_oracles = std::move(next_oracles);
  }
  run_tasks(previous.size(), 4, [&](std::size_t i) { previous[i].clear(); });
  EXPECT_EQ(this->heap_.stats().live_nodes, pool_nodes);
  for (std::size_t i = 0; i < kPool; ++i) EXPECT_TRUE(same_contents(pool[i], pool_oracles[i]));
}

// Many handles of one map, each edited at a different place, then every handle (the original
// among them) dropped at once: the last decrement of each shared node happens on whichever
// thread gets there last, and that thread frees it.
TYPED_TEST(LandmarkTreeConcurrencyTest, LastReferencesDroppedByManyThreadsAtOnce) {
  using Tree = typename TestFixture::TreeType;
  const int rounds = sized(200, 30);
  const std::size_t handles = 48;
  Failures failures;
  for (int round = 0; round < rounds; ++round) {
    Oracle oracle;
    std::vector<Tree> trees;
    trees.push_back(this->make_base(static_cast<std::size_t>(round % 5), oracle));
    for (std::size_t i = 1; i < handles; ++i) trees.push_back(trees[0]);
    // Copies and edits at once: each task edits its own handle, all share nodes.
    run_tasks(handles, 4, [&](std::size_t i) {
      if (i == 0) return;
      std::mt19937_64 rng(static_cast<std::uint64_t>(round) * 977u + i);
      Oracle mine = oracle;
      TestFixture::mutate(trees[i], mine, rng, 4, i, failures);
      if (!same_contents(trees[i], mine)) failures.add("handle " + std::to_string(i));
    });
    ASSERT_EQ(failures.count(), 0) << failures.first();
    ASSERT_TRUE(same_contents(trees[0], oracle));
    run_tasks(handles, 4, [&](std::size_t i) { trees[i].clear(); });
    ASSERT_EQ(this->heap_.stats().live_nodes, 0) << "round " << round;
  }
}

// Readers iterate and look up a shared map while writers copy it and edit their copies.
TYPED_TEST(LandmarkTreeConcurrencyTest, ReadersOfASharedMapSeeItUnchangedWhileCopiesChange) {
  using Tree = typename TestFixture::TreeType;
  Oracle oracle;
  const Tree shared = this->make_base(6, oracle);
  Failures failures;
  const std::size_t tasks = sized<std::size_t>(2000, 200);
  run_tasks(tasks, 4, [&](std::size_t i) {
    std::mt19937_64 rng(i);
    if (i % 2 == 0) {
      for (int pass = 0; pass < 3; ++pass) {
        if (!same_contents(shared, oracle)) failures.add("reader " + std::to_string(i));
      }
    } else {
      Tree copy = shared;
      Oracle copy_oracle = oracle;
      TestFixture::mutate(copy, copy_oracle, rng, 10, i, failures);
      if (!same_contents(copy, copy_oracle)) failures.add("writer " + std::to_string(i));
    }
  });
  EXPECT_EQ(failures.count(), 0) << failures.first();
  EXPECT_TRUE(same_contents(shared, oracle));
}

}  // namespace
}  // namespace fastslam::memory
