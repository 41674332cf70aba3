// Node heaps: where the nodes of the persistent trees come from, counted (live nodes and bytes)
// so tests can assert that every node was freed. `MallocHeap` goes to the process allocator
// (sized delete); `PoolHeap` keeps per-thread free lists by block size above it, so a path
// copy's free-then-allocate stays on the thread. A tree takes a `NodeHeap&`, so tests swap in
// failing or counting heaps.
// Ownership: a heap must outlive every block it handed out. Blocks of 16 bytes or more are
// 16-byte aligned.
// Thread safety: allocate, deallocate and stats are thread-safe; a block may be freed by any
// thread. Costs: allocate and deallocate O(1) (a short lock on a thread's first use of a
// heap; a thread-specific lookup when it last used another heap); stats() O(threads that used
// the heap), under a lock.
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
  // Unique over the process's life (never reused), so a thread's note of the heap it last used
  // cannot match a later heap at the same address.
  std::uint64_t id() const noexcept { return id_; }

 private:
  static std::uint64_t next_id() noexcept;
  const std::uint64_t id_ = next_id();

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
  Cache& local_cache();

  std::size_t max_cached_;
  tbb::enumerable_thread_specific<Cache, tbb::cache_aligned_allocator<Cache>,
                                  tbb::ets_key_per_instance>
      caches_;
};

}  // namespace fastslam::memory
