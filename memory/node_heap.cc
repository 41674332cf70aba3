#include "memory/node_heap.h"

#include <cstdlib>
#include <memory>
#include <mutex>
#include <new>

namespace fastslam::memory {
namespace {

void bump(std::atomic<std::int64_t>& counter, std::int64_t delta) noexcept {
  // Only the owning thread writes its counter, so load + store is enough (and cheaper than RMW).
  counter.store(counter.load(std::memory_order_relaxed) + delta, std::memory_order_relaxed);
}

// The heap this thread last used and its per-thread data there: one comparison per block on
// the hot path instead of a pthread_getspecific (a run allocates from one heap per filter).
struct LastUsed {
  std::uint64_t heap = 0;  // NodeHeap::id(); 0 is no heap's
  void* data = nullptr;
};
thread_local LastUsed last_counters;
thread_local LastUsed last_pool_cache;

std::atomic<std::uint64_t> heap_ids{1};

}  // namespace

std::uint64_t NodeHeap::next_id() noexcept {
  return heap_ids.fetch_add(1, std::memory_order_relaxed);
}

NodeHeap::Counters& NodeHeap::local_counters() {
  if (last_counters.heap == id_) return *static_cast<Counters*>(last_counters.data);
  Counters*& mine = local_.local();
  if (mine == nullptr) {
    auto fresh = std::make_unique<Counters>();
    std::lock_guard lock(registry_mutex_);
    registry_.push_back(std::move(fresh));
    mine = registry_.back().get();
  }
  last_counters = {id_, mine};
  return *mine;
}

void* NodeHeap::allocate(std::size_t bytes) {
  void* block = do_allocate(bytes);
  Counters& c = local_counters();
  bump(c.nodes, 1);
  bump(c.bytes, static_cast<std::int64_t>(bytes));
  bump(c.allocations, 1);
  return block;
}

void NodeHeap::deallocate(void* block, std::size_t bytes) noexcept {
  Counters& c = local_counters();
  bump(c.nodes, -1);
  bump(c.bytes, -static_cast<std::int64_t>(bytes));
  do_deallocate(block, bytes);
}

HeapStats NodeHeap::stats() const {
  HeapStats total;
  std::lock_guard lock(registry_mutex_);
  for (const std::unique_ptr<Counters>& c : registry_) {
    total.live_nodes += c->nodes.load(std::memory_order_relaxed);
    total.live_bytes += c->bytes.load(std::memory_order_relaxed);
    total.allocations += c->allocations.load(std::memory_order_relaxed);
  }
  return total;
}

void* MallocHeap::do_allocate(std::size_t bytes) { return ::operator new(bytes); }

void MallocHeap::do_deallocate(void* block, std::size_t bytes) noexcept {
  ::operator delete(block, bytes);
}

PoolHeap::PoolHeap(std::size_t max_cached_per_size) : max_cached_(max_cached_per_size) {}

PoolHeap::Cache& PoolHeap::local_cache() {
  if (last_pool_cache.heap == id()) return *static_cast<Cache*>(last_pool_cache.data);
  Cache& cache = caches_.local();
  last_pool_cache = {id(), &cache};
  return cache;
}

PoolHeap::~PoolHeap() {
  for (Cache& cache : caches_) {
    for (int k = 0; k < kSizeClasses; ++k) {
      while (FreeBlock* block = cache.head[k]) {
        cache.head[k] = block->next;
        ::operator delete(block, cache.size[k]);
      }
    }
  }
}

void* PoolHeap::do_allocate(std::size_t bytes) {
  if (bytes < sizeof(FreeBlock)) bytes = sizeof(FreeBlock);  // as do_deallocate files it
  Cache& cache = local_cache();
  for (int k = 0; k < kSizeClasses && cache.size[k] != 0; ++k) {
    if (cache.size[k] == bytes) {
      if (FreeBlock* block = cache.head[k]) {
        cache.head[k] = block->next;
        --cache.count[k];
        return block;
      }
      break;
    }
  }
  return ::operator new(bytes);
}

void PoolHeap::do_deallocate(void* block, std::size_t bytes) noexcept {
  if (bytes < sizeof(FreeBlock)) bytes = sizeof(FreeBlock);
  Cache& cache = local_cache();
  for (int k = 0; k < kSizeClasses; ++k) {
    if (cache.size[k] == 0) cache.size[k] = bytes;  // first free of a new size claims a class
    if (cache.size[k] == bytes) {
      if (cache.count[k] >= max_cached_) break;
      auto* free_block = static_cast<FreeBlock*>(block);
      free_block->next = cache.head[k];
      cache.head[k] = free_block;
      ++cache.count[k];
      return;
    }
  }
  ::operator delete(block, bytes);
}

}  // namespace fastslam::memory
