// The landmarks a scan's greedy association has taken so far (engine/association.cc and
// engine/internal/lazy_association.h): the first 32 in order in a short array, since scans are
// small and a linear look is cheapest; beyond that the assignment itself, which holds them all.
// Thread safety: thread-compatible. Costs: take O(1); contains O(min(taken, 32)), or O(Z) past
// 32 taken; no allocation.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "memory/landmark_tree.h"

namespace fastslam::engine::internal {

class TakenSlots {
 public:
  // `assignment`: observation -> slot taken (or a negative "new"), filled as slots are taken.
  explicit TakenSlots(std::span<const std::int64_t> assignment) : assignment_(assignment) {}

  bool contains(memory::Slot slot) const {
    if (count_ <= kListed) {
      return std::find(listed_.begin(), listed_.begin() + count_, slot) != listed_.begin() + count_;
    }
    return std::find(assignment_.begin(), assignment_.end(), static_cast<std::int64_t>(slot)) !=
           assignment_.end();
  }
  void take(memory::Slot slot) {
    if (count_ < kListed) listed_[count_] = slot;
    ++count_;
  }
  std::size_t size() const { return count_; }

 private:
  static constexpr std::size_t kListed = 32;
  std::array<memory::Slot, kListed> listed_;
  std::size_t count_ = 0;
  std::span<const std::int64_t> assignment_;
};

}  // namespace fastslam::engine::internal
