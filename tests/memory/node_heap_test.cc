// The node heaps: exact counters (live nodes, live bytes, allocations) on one thread and across
// threads, including blocks freed by a thread other than their allocator and stats() read while
// other threads allocate; alignment; PoolHeap's reuse of freed blocks, its per-size cap, and
// the return of every cached block to the process allocator when the heap dies (checked here
// with a counting global operator new, and by ASan's leak checker in the asan preset).
// Labelled "concurrency" (runs under ThreadSanitizer too): threads are plain std::threads.
#include "memory/node_heap.h"

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <mutex>
#include <new>
#include <set>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "tests/memory/heap_fixtures.h"

// Counting replacement of the global allocation functions: every block MallocHeap and PoolHeap
// take from (and give back to) the process allocator goes through these.
namespace {
std::atomic<std::int64_t> g_live_blocks{0};

void* counted_new(std::size_t bytes) {
  void* block = std::malloc(bytes == 0 ? 1 : bytes);
  if (block == nullptr) throw std::bad_alloc();
  g_live_blocks.fetch_add(1, std::memory_order_relaxed);
  return block;
}
void counted_delete(void* block) noexcept {
  if (block == nullptr) return;
  g_live_blocks.fetch_sub(1, std::memory_order_relaxed);
  std::free(block);
}
}  // namespace

void* operator new(std::size_t bytes) { return counted_new(bytes); }
void* operator new[](std::size_t bytes) { return counted_new(bytes); }
void operator delete(void* block) noexcept { counted_delete(block); }
void operator delete[](void* block) noexcept { counted_delete(block); }
void operator delete(void* block, std::size_t) noexcept { counted_delete(block); }
void operator delete[](void* block, std::size_t) noexcept { counted_delete(block); }

namespace fastslam::memory {
namespace {

using testing::sized;

std::int64_t live_blocks() { return g_live_blocks.load(std::memory_order_relaxed); }

template <class Heap>
class NodeHeapTest : public ::testing::Test {};
using Heaps = ::testing::Types<MallocHeap, PoolHeap>;
struct HeapName {
  template <class Heap>
  static std::string GetName(int) {  // NOLINT(readability-identifier-naming): gtest's name
    return std::is_same_v<Heap, PoolHeap> ? "Pool" : "Malloc";
  }
};
TYPED_TEST_SUITE(NodeHeapTest, Heaps, HeapName);

struct Block {
  void* block;
  std::size_t bytes;
};

TYPED_TEST(NodeHeapTest, CountersAreExactOnOneThread) {
  TypeParam heap;
  EXPECT_EQ(heap.stats().live_nodes, 0);
  EXPECT_EQ(heap.stats().live_bytes, 0);
  EXPECT_EQ(heap.stats().allocations, 0);
  std::vector<Block> blocks;
  std::int64_t bytes = 0;
  const std::size_t sizes[] = {24, 136, 264, 8, 1000, 72, 24, 264};
  for (int round = 0; round < 3; ++round) {
    for (std::size_t size : sizes) {
      blocks.push_back({heap.allocate(size), size});
      bytes += static_cast<std::int64_t>(size);
    }
  }
  HeapStats stats = heap.stats();
  EXPECT_EQ(stats.live_nodes, static_cast<std::int64_t>(blocks.size()));
  EXPECT_EQ(stats.live_bytes, bytes);
  EXPECT_EQ(stats.allocations, static_cast<std::int64_t>(blocks.size()));
  // Free every other block, then allocate a few again.
  std::int64_t freed_bytes = 0;
  for (std::size_t i = 0; i < blocks.size(); i += 2) {
    heap.deallocate(blocks[i].block, blocks[i].bytes);
    freed_bytes += static_cast<std::int64_t>(blocks[i].bytes);
  }
  const std::int64_t freed = static_cast<std::int64_t>((blocks.size() + 1) / 2);
  stats = heap.stats();
  EXPECT_EQ(stats.live_nodes, static_cast<std::int64_t>(blocks.size()) - freed);
  EXPECT_EQ(stats.live_bytes, bytes - freed_bytes);
  EXPECT_EQ(stats.allocations, static_cast<std::int64_t>(blocks.size()));
  for (std::size_t i = 0; i < blocks.size(); i += 2) {
    blocks[i].block = heap.allocate(blocks[i].bytes);
  }
  EXPECT_EQ(heap.stats().allocations, static_cast<std::int64_t>(blocks.size()) + freed);
  for (const Block& b : blocks) heap.deallocate(b.block, b.bytes);
  stats = heap.stats();
  EXPECT_EQ(stats.live_nodes, 0);
  EXPECT_EQ(stats.live_bytes, 0);
  EXPECT_EQ(stats.allocations, static_cast<std::int64_t>(blocks.size()) + freed);
}

TYPED_TEST(NodeHeapTest, BlocksOfSixteenBytesOrMoreAreSixteenByteAligned) {
  TypeParam heap;
  std::vector<Block> blocks;
  // Every node size is 16 bytes or more (the smallest inner node is 24 bytes); smaller blocks
  // are aligned as malloc aligns them (jemalloc: 8 bytes).
  for (std::size_t size = 1; size <= 600; size += 7) {
    void* block = heap.allocate(size);
    if (size >= 16) {
      EXPECT_EQ(reinterpret_cast<std::uintptr_t>(block) % 16, 0u) << size << " bytes";
    }
    std::memset(block, 0xab, size);  // ASan checks the whole block is ours
    blocks.push_back({block, size});
  }
  for (const Block& b : blocks) heap.deallocate(b.block, b.bytes);
  EXPECT_EQ(heap.stats().live_nodes, 0);
}

// Threads allocate; every block is then freed by a different thread; counters sum exactly.
TYPED_TEST(NodeHeapTest, CountersAreExactWhenBlocksAreFreedOnAnotherThread) {
  TypeParam heap;
  constexpr int kThreads = 4;
  const int per_thread = sized(20'000, 3'000);
  std::vector<std::vector<Block>> blocks(kThreads);
  auto size_of = [](int t, int i) { return static_cast<std::size_t>(8 + 16 * ((t + i) % 9)); };
  std::int64_t bytes = 0;
  for (int t = 0; t < kThreads; ++t) {
    for (int i = 0; i < per_thread; ++i) bytes += static_cast<std::int64_t>(size_of(t, i));
  }
  {
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) {
      threads.emplace_back([&, t] {
        for (int i = 0; i < per_thread; ++i) {
          blocks[t].push_back({heap.allocate(size_of(t, i)), size_of(t, i)});
        }
      });
    }
    for (std::thread& thread : threads) thread.join();
  }
  HeapStats stats = heap.stats();
  EXPECT_EQ(stats.live_nodes, std::int64_t{kThreads} * per_thread);
  EXPECT_EQ(stats.live_bytes, bytes);
  EXPECT_EQ(stats.allocations, std::int64_t{kThreads} * per_thread);
  {
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) {
      threads.emplace_back([&, t] {
        for (const Block& b : blocks[(t + 1) % kThreads]) heap.deallocate(b.block, b.bytes);
      });
    }
    for (std::thread& thread : threads) thread.join();
  }
  stats = heap.stats();
  EXPECT_EQ(stats.live_nodes, 0);
  EXPECT_EQ(stats.live_bytes, 0);
  EXPECT_EQ(stats.allocations, std::int64_t{kThreads} * per_thread);
}

// Producers allocate and hand blocks over a queue to consumers that free them, while another
// thread reads stats(): every reading is within bounds, and the end state is exact.
TYPED_TEST(NodeHeapTest, StatsAreReadableWhileOtherThreadsAllocateAndFree) {
  TypeParam heap;
  constexpr int kProducers = 2;
  constexpr int kConsumers = 2;
  const int per_producer = sized(50'000, 5'000);
  std::mutex mutex;
  std::vector<void*> queue;
  std::atomic<int> producers_done{0};
  std::atomic<bool> stop_reader{false};
  std::atomic<int> bad_readings{0};
  std::atomic<int> readings{0};
  const std::int64_t max_live = std::int64_t{kProducers} * per_producer;
  std::vector<std::thread> threads;
  threads.emplace_back([&] {
    std::int64_t last_allocations = 0;
    while (!stop_reader.load()) {
      const HeapStats s = heap.stats();
      // Per-thread counters are read one after another, so a block allocated on one thread and
      // freed on another may be seen freed and not yet allocated: live counts may dip below 0
      // by at most the blocks in flight. Allocations only grow.
      if (s.allocations < last_allocations || s.allocations > max_live || s.live_nodes > max_live ||
          s.live_nodes < -max_live) {
        bad_readings.fetch_add(1);
      }
      last_allocations = s.allocations;
      readings.fetch_add(1);
    }
  });
  for (int p = 0; p < kProducers; ++p) {
    threads.emplace_back([&] {
      // The reader has read once before any block moves, so the test sees readings however
      // the threads are scheduled (a loaded machine once ran the producers first).
      while (readings.load() == 0) std::this_thread::yield();
      for (int i = 0; i < per_producer; ++i) {
        void* block = heap.allocate(64);
        std::lock_guard lock(mutex);
        queue.push_back(block);
      }
      producers_done.fetch_add(1);
    });
  }
  for (int c = 0; c < kConsumers; ++c) {
    threads.emplace_back([&] {
      for (;;) {
        void* block = nullptr;
        {
          std::lock_guard lock(mutex);
          if (!queue.empty()) {
            block = queue.back();
            queue.pop_back();
          }
        }
        if (block != nullptr) {
          heap.deallocate(block, 64);
        } else if (producers_done.load() == kProducers) {
          std::lock_guard lock(mutex);
          if (queue.empty()) break;
        } else {
          std::this_thread::yield();
        }
      }
    });
  }
  for (std::size_t t = 1; t < threads.size(); ++t) threads[t].join();
  stop_reader.store(true);
  threads[0].join();
  EXPECT_EQ(bad_readings.load(), 0);
  EXPECT_GT(readings.load(), 0);
  const HeapStats stats = heap.stats();
  EXPECT_EQ(stats.live_nodes, 0);
  EXPECT_EQ(stats.live_bytes, 0);
  EXPECT_EQ(stats.allocations, max_live);
}

// Each heap holds thread-specific storage (a TLS key per instance): creating and destroying
// many heaps one after another must not run out of keys.
TYPED_TEST(NodeHeapTest, ManyHeapsOneAfterAnother) {
  for (int i = 0; i < 3000; ++i) {
    TypeParam heap;
    void* block = heap.allocate(40);
    heap.deallocate(block, 40);
    ASSERT_EQ(heap.stats().allocations, 1) << "heap " << i;
  }
}

// A thread remembers the heap it last used (NodeHeap::id); a later heap built at the very same
// address must count from zero, not into the dead heap's counters.
TYPED_TEST(NodeHeapTest, AHeapAtADeadHeapsAddressCountsAlone) {
  alignas(TypeParam) unsigned char storage[sizeof(TypeParam)];
  for (int round = 0; round < 4; ++round) {
    auto* heap = ::new (storage) TypeParam;
    void* block = heap->allocate(40);
    const HeapStats stats = heap->stats();
    EXPECT_EQ(stats.allocations, 1) << "round " << round;
    EXPECT_EQ(stats.live_nodes, 1) << "round " << round;
    heap->deallocate(block, 40);
    EXPECT_EQ(heap->stats().live_nodes, 0) << "round " << round;
    heap->~TypeParam();
  }
}

// Threads switching between two live heaps: each heap's counts are its own.
TYPED_TEST(NodeHeapTest, ThreadsAlternatingBetweenHeapsCountEachAlone) {
  TypeParam a;
  TypeParam b;
  std::vector<void*> from_a;
  std::vector<void*> from_b;
  for (int i = 0; i < 100; ++i) {
    from_a.push_back(a.allocate(48));
    from_b.push_back(b.allocate(48));
    from_b.push_back(b.allocate(80));
  }
  std::thread other([&] {
    for (int i = 0; i < 50; ++i) {
      a.deallocate(from_a[i], 48);
      b.deallocate(from_b[2 * i], 48);
    }
    from_a.push_back(a.allocate(48));
  });
  other.join();
  EXPECT_EQ(a.stats().live_nodes, 51);
  EXPECT_EQ(a.stats().allocations, 101);
  EXPECT_EQ(b.stats().live_nodes, 150);
  EXPECT_EQ(b.stats().live_bytes, 50 * 48 + 100 * 80);
  for (std::size_t i = 50; i < from_a.size(); ++i) a.deallocate(from_a[i], 48);
  for (int i = 0; i < 100; ++i) {
    if (i >= 50) b.deallocate(from_b[2 * i], 48);
    b.deallocate(from_b[2 * i + 1], 80);
  }
  EXPECT_EQ(a.stats().live_nodes, 0);
  EXPECT_EQ(b.stats().live_nodes, 0);
  EXPECT_EQ(b.stats().live_bytes, 0);
}

TEST(PoolHeap, ReusesTheLastFreedBlockOfTheSameSize) {
  PoolHeap heap;
  void* a = heap.allocate(264);
  void* b = heap.allocate(264);
  void* small = heap.allocate(136);
  heap.deallocate(a, 264);
  heap.deallocate(b, 264);
  heap.deallocate(small, 136);
  EXPECT_EQ(heap.allocate(264), b);  // last in, first out
  EXPECT_EQ(heap.allocate(264), a);
  EXPECT_EQ(heap.allocate(136), small);
  heap.deallocate(a, 264);
  heap.deallocate(b, 264);
  heap.deallocate(small, 136);
  // Sizes never mix: a 136-byte request does not get a freed 264-byte block.
  void* c = heap.allocate(136);
  EXPECT_EQ(c, small);
  void* d = heap.allocate(136);
  EXPECT_NE(d, a);
  EXPECT_NE(d, b);
  heap.deallocate(c, 136);
  heap.deallocate(d, 136);
  EXPECT_EQ(heap.stats().live_nodes, 0);
}

TEST(PoolHeap, ReusesTinyBlocks) {
  PoolHeap heap;
  void* a = heap.allocate(1);
  heap.deallocate(a, 1);
  EXPECT_EQ(heap.allocate(1), a);
  heap.deallocate(a, 1);
  EXPECT_EQ(heap.stats().live_bytes, 0);
}

// A heap's first use on a thread registers that thread's counters (a bookkeeping allocation);
// warm the heap up with a block of an unrelated size before counting blocks.
void warm_up(NodeHeap& heap) { heap.deallocate(heap.allocate(24), 24); }

TEST(PoolHeap, CachesAtMostTheGivenNumberOfBlocksPerSize) {
  {
    PoolHeap heap(2);
    warm_up(heap);
    const std::int64_t before = live_blocks();
    void* a = heap.allocate(100);
    void* b = heap.allocate(100);
    void* c = heap.allocate(100);
    EXPECT_EQ(live_blocks() - before, 3);
    heap.deallocate(a, 100);
    heap.deallocate(b, 100);
    heap.deallocate(c, 100);  // over the cap: back to the process allocator
    EXPECT_EQ(live_blocks() - before, 2);
    EXPECT_EQ(heap.allocate(100), b);
    EXPECT_EQ(heap.allocate(100), a);
    EXPECT_EQ(live_blocks() - before, 2);
    heap.deallocate(a, 100);
    heap.deallocate(b, 100);
  }
  {
    PoolHeap no_cache(0);
    warm_up(no_cache);
    const std::int64_t before = live_blocks();
    void* a = no_cache.allocate(100);
    no_cache.deallocate(a, 100);
    EXPECT_EQ(live_blocks(), before);
  }
}

TEST(PoolHeap, ReusesBlocksFreedByThisThreadWhateverThreadAllocatedThem) {
  PoolHeap heap;
  void* block = nullptr;
  std::thread([&] { block = heap.allocate(72); }).join();
  heap.deallocate(block, 72);  // into this thread's cache
  EXPECT_EQ(heap.allocate(72), block);
  heap.deallocate(block, 72);
  HeapStats stats = heap.stats();
  EXPECT_EQ(stats.live_nodes, 0);
  EXPECT_EQ(stats.allocations, 2);
}

// Cached blocks, on every thread and in more sizes than the pool has classes, all go back to
// the process allocator when the heap dies.
TEST(PoolHeap, ReturnsEveryCachedBlockWhenDestroyed) {
  const std::int64_t before = live_blocks();
  {
    PoolHeap heap;
    auto churn = [&heap](int salt) {
      std::vector<Block> blocks;
      for (int i = 0; i < 2000; ++i) {
        const std::size_t size = static_cast<std::size_t>(16 * (1 + (i + salt) % 12));
        blocks.push_back({heap.allocate(size), size});
      }
      for (const Block& b : blocks) heap.deallocate(b.block, b.bytes);
    };
    churn(0);
    std::thread other(churn, 5);
    other.join();
    EXPECT_EQ(heap.stats().live_nodes, 0);
    EXPECT_GT(live_blocks() - before, 0);  // cached, not yet returned
  }
  EXPECT_EQ(live_blocks(), before);
}

TEST(MallocHeap, GivesEveryBlockBackAtOnce) {
  MallocHeap heap;
  warm_up(heap);
  const std::int64_t before = live_blocks();
  void* a = heap.allocate(264);
  EXPECT_EQ(live_blocks() - before, 1);
  heap.deallocate(a, 264);
  EXPECT_EQ(live_blocks(), before);
}

}  // namespace
}  // namespace fastslam::memory
