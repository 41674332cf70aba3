// Reference counts of the shared nodes of persistent structures (LandmarkTree, SpatialIndex),
// as policies a test can swap. A node starts with one reference; `acquire` adds one, `release`
// drops one and says whether it was the last (the caller then owns the node and frees it), and
// `unique` says whether the holder may write the node in place.
// Thread safety: `AtomicRefcount` may be acquired and released from any threads at once
// (relaxed increment, acquire-release decrement, acquire load in `unique`, as immer's
// refcount_policy); `LocalRefcount` is for nodes that never cross threads, and for tests that
// run one suite over both. Costs: O(1), no allocation.
#pragma once

#include <atomic>
#include <cstdint>

namespace fastslam::memory {

struct AtomicRefcount {
  std::atomic<std::uint32_t> count{1};
  void acquire() noexcept { count.fetch_add(1, std::memory_order_relaxed); }
  // True when this was the last reference: the caller then owns the node and frees it.
  bool release() noexcept { return count.fetch_sub(1, std::memory_order_acq_rel) == 1; }
  // Acquire: writes of the thread that dropped the count to one happen before ours.
  bool unique() const noexcept { return count.load(std::memory_order_acquire) == 1; }
  // The references held now: exact only while no other thread changes them.
  std::uint32_t use_count() const noexcept { return count.load(std::memory_order_acquire); }
};

struct LocalRefcount {
  std::uint32_t count = 1;
  void acquire() noexcept { ++count; }
  bool release() noexcept { return --count == 0; }
  bool unique() const noexcept { return count == 1; }
  std::uint32_t use_count() const noexcept { return count; }
};

}  // namespace fastslam::memory
