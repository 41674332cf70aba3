// Node heaps: where the nodes of the persistent landmark trees come from.
//
// A heap hands out fixed-size blocks to the trees and counts what is live (nodes and bytes), so
// tests can assert that every node was freed and benchmarks can report memory. The trees take a
// `NodeHeap&` at construction, so a test swaps the heap (failure injection, counting) without
// touching the tree. Two heaps ship:
//   - `MallocHeap`: straight to the process allocator (jemalloc in every executable we ship, the
//     sanitizer's allocator under ASan/TSan), sized delete.
//   - `PoolHeap`: per-thread free lists by block size above `MallocHeap`, so the hot path of a
//     path copy (free a node in one step, allocate one the next) never leaves the thread.
//
// Ownership: a heap must outlive every block it handed out (every tree built on it). Blocks of
// 16 bytes or more (every tree node) are 16-byte aligned; smaller ones as malloc aligns them.
// Thread safety: `allocate`, `deallocate` and `stats` may be called from any number of threads
// at once; a block may be freed by a thread other than the one that allocated it.
// Costs: allocate/deallocate are O(1) and lock-free apart from what malloc does (and a short
// lock on a thread's first use of the heap); counting is relaxed per-thread stores. `stats()`
// takes a lock and is O(threads that ever used the heap).
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <vector>

#include <oneapi/tbb/cache_aligned_allocator.h>
#include <oneapi/tbb/enumerable_thread_specific.h>

namespace fastslam::memory {

// What a heap holds right now, summed over threads.
struct HeapStats {
  std::int64_t live_nodes = 0;   // blocks allocated and not yet freed
  std::int64_t live_bytes = 0;   // bytes in those blocks, as requested by the trees
  std::int64_t allocations = 0;  // blocks allocated since construction
};

// The heap interface. Non-virtual entry points count; derived heaps supply the blocks.
class NodeHeap {
 public:
  NodeHeap() = default;
  NodeHeap(const NodeHeap&) = delete;
  NodeHeap& operator=(const NodeHeap&) = delete;
  virtual ~NodeHeap() = default;

  // Returns a block of `bytes` bytes, 16-byte aligned when bytes >= 16. Throws std::bad_alloc
  // when out of memory.
  void* allocate(std::size_t bytes);
  // REQUIRES: `block` came from `allocate(bytes)` on this heap and was not freed since.
  void deallocate(void* block, std::size_t bytes) noexcept;

  HeapStats stats() const;

 protected:
  virtual void* do_allocate(std::size_t bytes) = 0;
  virtual void do_deallocate(void* block, std::size_t bytes) noexcept = 0;

 private:
  // Written only by the owning thread (relaxed load + store, no read-modify-write); atomics so
  // that `stats()` from another thread is not a data race.
  struct alignas(64) Counters {
    std::atomic<std::int64_t> nodes{0};
    std::atomic<std::int64_t> bytes{0};
    std::atomic<std::int64_t> allocations{0};
  };
  // This thread's counters, created (and registered) on its first use of the heap.
  Counters& local_counters();

  // Thread -> its counters: lock-free lookup on the hot path. Never iterated: iterating an
  // enumerable_thread_specific while another thread adds its element reads that element while
  // it is being constructed; `stats()` walks `registry_` instead, where counters appear fully
  // built, under `registry_mutex_`.
  tbb::enumerable_thread_specific<Counters*, tbb::cache_aligned_allocator<Counters*>,
                                  tbb::ets_key_per_instance>
      local_;  // elements start as nullptr (value-initialised)
  mutable std::mutex registry_mutex_;
  std::vector<std::unique_ptr<Counters>> registry_;  // guarded by registry_mutex_
};

// Blocks from the process allocator (jemalloc where linked).
class MallocHeap final : public NodeHeap {
 protected:
  void* do_allocate(std::size_t bytes) override;
  void do_deallocate(void* block, std::size_t bytes) noexcept override;
};

// Per-thread free lists, one per block size, above the process allocator. Each thread keeps at
// most `max_cached_per_size` free blocks of a size; beyond that blocks go back to malloc.
// Cached blocks are returned to malloc when the heap is destroyed.
class PoolHeap final : public NodeHeap {
 public:
  explicit PoolHeap(std::size_t max_cached_per_size = 1 << 14);
  ~PoolHeap() override;

 protected:
  void* do_allocate(std::size_t bytes) override;
  void do_deallocate(void* block, std::size_t bytes) noexcept override;

 private:
  static constexpr int kSizeClasses = 8;  // distinct block sizes cached; others go to malloc
  struct FreeBlock {
    FreeBlock* next;
  };
  struct Cache {
    std::size_t size[kSizeClasses] = {};
    FreeBlock* head[kSizeClasses] = {};
    std::size_t count[kSizeClasses] = {};
  };
  std::size_t max_cached_;
  tbb::enumerable_thread_specific<Cache, tbb::cache_aligned_allocator<Cache>,
                                  tbb::ets_key_per_instance>
      caches_;
};

}  // namespace fastslam::memory
