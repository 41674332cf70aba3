// Test-only helpers for the memory/ suites: a heap that fails on demand (as immer's dada), the
// policy x heap combinations the generic suites run over, a fixture that checks for leaked
// nodes after every test, the `std::map` oracle and its comparison, an independent count of
// the nodes a set of root-to-leaf paths holds, and a "run on many threads" helper (TBB tasks,
// or plain std::threads under ThreadSanitizer, which cannot see TBB's internal hand-offs).
//
// Not API: included by the tests in this folder only.
// Thread safety: `FailingHeap` is for single-threaded tests; everything else is stateless or
// thread-compatible.
#pragma once

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <map>
#include <new>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/global_control.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/partitioner.h>
#include <oneapi/tbb/task_arena.h>

#include "memory/landmark_tree.h"
#include "memory/node_heap.h"

#if defined(__SANITIZE_THREAD__)
#define FASTSLAM_TEST_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define FASTSLAM_TEST_TSAN 1
#endif
#endif

namespace fastslam::memory::testing {

#if defined(__SANITIZE_THREAD__) || defined(__SANITIZE_ADDRESS__)
inline constexpr bool kSanitized = true;
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer) || __has_feature(address_sanitizer)
inline constexpr bool kSanitized = true;
#else
inline constexpr bool kSanitized = false;
#endif
#else
inline constexpr bool kSanitized = false;
#endif

#if defined(FASTSLAM_TEST_TSAN)
inline constexpr bool kThreadSanitized = true;
#else
inline constexpr bool kThreadSanitized = false;
#endif

// `full` in an optimised build, `small` under a sanitizer (same checks, smaller sizes).
template <class T>
constexpr T sized(T full, T small) {
  return kSanitized ? small : full;
}

// ---------------------------------------------------------------------------------------------
// Heaps

// Forwards to another heap and throws std::bad_alloc on the k-th allocation after `fail_at(k)`
// (k = 1: the next one). Disarmed by default and after it fired.
class FailingHeap final : public NodeHeap {
 public:
  explicit FailingHeap(NodeHeap& inner) : inner_(&inner) {}

  void fail_at(std::int64_t k) { countdown_ = k; }
  void disarm() { countdown_ = 0; }
  // Allocation attempts seen (including the one that threw).
  std::int64_t attempts() const { return attempts_; }

 protected:
  void* do_allocate(std::size_t bytes) override {
    ++attempts_;
    if (countdown_ > 0 && --countdown_ == 0) throw std::bad_alloc();
    return inner_->allocate(bytes);
  }
  void do_deallocate(void* block, std::size_t bytes) noexcept override {
    inner_->deallocate(block, bytes);
  }

 private:
  NodeHeap* inner_;
  std::int64_t countdown_ = 0;
  std::int64_t attempts_ = 0;
};

// ---------------------------------------------------------------------------------------------
// Policy x heap combinations

template <class P, class H>
struct Config {
  using Policy = P;
  using Tree = BasicLandmarkTree<P>;
  using Heap = H;
};

template <class R>
constexpr const char* refcount_name() {
  return std::is_same_v<R, AtomicRefcount> ? "Atomic" : "Local";
}

// Readable typed-test names: "I4L2Atomic_Pool".
struct ConfigName {
  template <class C>
  static std::string GetName(int) {  // NOLINT(readability-identifier-naming): gtest's name
    std::ostringstream name;
    name << "I" << C::Policy::kInnerBits << "L" << C::Policy::kLeafBits
         << refcount_name<typename C::Policy::RefcountType>() << "_"
         << (std::is_same_v<typename C::Heap, PoolHeap> ? "Pool" : "Malloc");
    return name.str();
  }
};

// A fixture owning the heap of type `C::Heap`; after every test, every node must be freed.
template <class C>
class HeapLeakCheck : public ::testing::Test {
 protected:
  void TearDown() override {
    const HeapStats stats = heap_.stats();
    EXPECT_EQ(stats.live_nodes, 0) << "nodes leaked";
    EXPECT_EQ(stats.live_bytes, 0) << "bytes leaked";
  }
  typename C::Heap heap_;
};

// ---------------------------------------------------------------------------------------------
// Shape arithmetic, computed from the slot bits alone (independent of the tree's code)

template <class Tree>
constexpr std::uint64_t capacity_at(unsigned height) {
  return std::uint64_t{Tree::kLeafWidth} << (Tree::kInnerBits * height);
}

// The height (inner levels) of a tree whose slots [0, n) are all used, n >= 1.
template <class Tree>
unsigned minimal_height(std::uint64_t n) {
  unsigned h = 0;
  while (capacity_at<Tree>(h) < n) ++h;
  return h;
}

// Nodes of a tree of the given height whose slots [0, n) are all used.
template <class Tree>
std::int64_t dense_node_count(std::uint64_t n, unsigned height) {
  std::int64_t nodes = 0;
  for (unsigned j = 0; j <= height; ++j) {
    const std::uint64_t span = capacity_at<Tree>(j);  // slots under one node of level j
    nodes += static_cast<std::int64_t>((n + span - 1) / span);
  }
  return nodes;
}

// A node on a root-to-leaf path, as (level above the leaves, slot prefix).
using NodeKey = std::pair<unsigned, std::uint64_t>;

template <class Tree>
void add_path(Slot slot, unsigned height, std::set<NodeKey>& nodes) {
  for (unsigned j = 0; j <= height; ++j) {
    nodes.insert({j, std::uint64_t{slot} >> (Tree::kLeafBits + Tree::kInnerBits * j)});
  }
}

template <class Tree>
std::set<NodeKey> path_set(const std::vector<Slot>& slots, unsigned height) {
  std::set<NodeKey> nodes;
  for (Slot s : slots) add_path<Tree>(s, height, nodes);
  return nodes;
}

// Distinct nodes on the union of the root-to-leaf paths of `slots`; inner nodes separately.
struct PathCount {
  std::int64_t nodes = 0;
  std::int64_t inner = 0;
  std::int64_t leaves = 0;
};
template <class Tree>
PathCount path_union(const std::vector<Slot>& slots, unsigned height) {
  std::set<NodeKey> nodes;
  for (Slot s : slots) add_path<Tree>(s, height, nodes);
  PathCount count;
  count.nodes = static_cast<std::int64_t>(nodes.size());
  for (const NodeKey& key : nodes) (key.first == 0 ? count.leaves : count.inner) += 1;
  return count;
}

// The byte sizes of a leaf and of an inner node, as the heap sees them.
struct NodeBytes {
  std::int64_t leaf = 0;
  std::int64_t inner = 0;
};
template <class Tree>
NodeBytes node_bytes() {
  MallocHeap heap;
  NodeBytes bytes;
  Tree tree(heap);
  tree.insert(Landmark{});
  bytes.leaf = heap.stats().live_bytes;  // one leaf
  for (unsigned i = 1; i <= Tree::kLeafWidth; ++i) tree.insert(Landmark{});
  bytes.inner = heap.stats().live_bytes - 2 * bytes.leaf;  // two leaves under one root
  return bytes;
}

// ---------------------------------------------------------------------------------------------
// The oracle: a std::map per particle, copied the naive way

using Oracle = std::map<Slot, Landmark>;

inline Slot lowest_free(const Oracle& oracle) {
  Slot expected = 0;
  for (const auto& entry : oracle) {
    if (entry.first != expected) break;
    ++expected;
  }
  return expected;
}

inline Landmark random_landmark(std::mt19937_64& rng, std::uint64_t id) {
  std::uniform_real_distribution<double> u(-100.0, 100.0);
  Landmark l;
  l.x = u(rng);
  l.y = u(rng);
  l.sxx = u(rng);
  l.sxy = u(rng);
  l.syy = u(rng);
  l.log_odds = u(rng);
  l.id = id;
  l.last_seen = static_cast<std::int64_t>(rng() & 0xffff);
  return l;
}

// One change a scan makes to a particle's tree: an insert (always on an empty tree; the new
// landmark's id is `id`), an edit or an erase of a random landmark, a third each.
template <class Tree>
void random_scan_change(Tree& tree, std::mt19937_64& rng, std::uint64_t id) {
  const int kind = static_cast<int>(rng() % 3);
  if (kind == 0 || tree.empty()) {
    tree.insert(random_landmark(rng, id));
    return;
  }
  auto it = tree.begin();
  for (std::uint64_t skip = rng() % tree.size(); skip > 0; --skip) ++it;
  const Slot slot = (*it).slot;
  if (kind == 1) {
    tree.edit(slot).x += 1.0;
  } else {
    tree.erase(slot);
  }
}

// A deterministic landmark for (tag, slot): lets many threads check contents with no oracle.
inline Landmark tagged_landmark(std::uint64_t tag, Slot slot) {
  Landmark l;
  l.x = static_cast<double>(slot);
  l.y = static_cast<double>(tag);
  l.id = tag << 32 | slot;
  l.last_seen = static_cast<std::int64_t>(tag ^ slot);
  return l;
}

// Every read of `tree` against `oracle`: size, empty, ordered iteration (slot and landmark),
// find/contains/at on every slot held and on the free slots around them.
template <class Tree>
::testing::AssertionResult same_contents(const Tree& tree, const Oracle& oracle) {
  if (tree.size() != oracle.size() || tree.empty() != oracle.empty()) {
    return ::testing::AssertionFailure()
           << "size " << tree.size() << ", oracle size " << oracle.size();
  }
  auto expected = oracle.begin();
  std::size_t visited = 0;
  for (auto it = tree.begin(); it != tree.end(); ++it, ++expected, ++visited) {
    if (expected == oracle.end()) {
      return ::testing::AssertionFailure() << "iteration yields more than " << oracle.size();
    }
    const auto entry = *it;
    if (entry.slot != expected->first) {
      return ::testing::AssertionFailure() << "iteration step " << visited << " yields slot "
                                           << entry.slot << ", oracle " << expected->first;
    }
    if (!(entry.landmark == expected->second)) {
      return ::testing::AssertionFailure() << "iteration: landmark of slot " << entry.slot;
    }
  }
  if (expected != oracle.end()) {
    return ::testing::AssertionFailure()
           << "iteration stops after " << visited << " of " << oracle.size();
  }
  Slot previous_end = 0;
  for (const auto& [slot, landmark] : oracle) {
    const Landmark* found = tree.find(slot);
    if (found == nullptr || !(*found == landmark) || !tree.contains(slot) ||
        &tree.at(slot) != found) {
      return ::testing::AssertionFailure() << "find/contains/at of held slot " << slot;
    }
    for (Slot gap = previous_end; gap < slot; ++gap) {
      if (tree.find(gap) != nullptr || tree.contains(gap)) {
        return ::testing::AssertionFailure() << "free slot " << gap << " is found";
      }
    }
    previous_end = slot + 1;
  }
  for (Slot beyond = previous_end; beyond < previous_end + 2 * Tree::kLeafWidth + 3; ++beyond) {
    if (tree.find(beyond) != nullptr) {
      return ::testing::AssertionFailure() << "slot " << beyond << " beyond the last is found";
    }
  }
  return ::testing::AssertionSuccess();
}

// ---------------------------------------------------------------------------------------------
// Concurrency

// Calls task(i) for every i in [0, tasks), concurrently on `threads` threads: TBB tasks (one
// per i) inside a task_arena, or plain std::threads under ThreadSanitizer (Debian's libtbb is
// not instrumented, so TSan would report TBB's own hand-offs as races: google/sanitizers#1004).
template <class Task>
void run_tasks(std::size_t tasks, int threads, const Task& task) {
#if defined(FASTSLAM_TEST_TSAN)
  std::atomic<std::size_t> next{0};
  auto worker = [&] {
    for (std::size_t i = next.fetch_add(1); i < tasks; i = next.fetch_add(1)) task(i);
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(worker);
  worker();
  for (std::thread& thread : pool) thread.join();
#else
  // Lift TBB's worker limit (hardware threads - 1) so `threads` threads really run, even on a
  // two-core machine: more threads than cores gives more interleavings.
  tbb::global_control workers(tbb::global_control::max_allowed_parallelism,
                              static_cast<std::size_t>(threads));
  tbb::task_arena arena(threads);
  arena.execute([&] {
    tbb::parallel_for(
        tbb::blocked_range<std::size_t>(0, tasks, 1),
        [&](const tbb::blocked_range<std::size_t>& r) {
          for (std::size_t i = r.begin(); i != r.end(); ++i) task(i);
        },
        tbb::simple_partitioner());
  });
#endif
}

}  // namespace fastslam::memory::testing
