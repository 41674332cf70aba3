#include "memory/landmark_tree.h"

#include <gtest/gtest.h>

namespace fastslam::memory {
namespace {
TEST(LandmarkTree, Smoke) {
  MallocHeap heap;
  {
    LandmarkTree t(heap);
    for (int i = 0; i < 1000; ++i) {
      Landmark l;
      l.id = static_cast<std::uint64_t>(i);
      EXPECT_EQ(t.insert(l), static_cast<Slot>(i));
    }
    LandmarkTree c = t;
    c.edit(500).x = 3;
    EXPECT_EQ(t.at(500).x, 0);
    EXPECT_EQ(c.at(500).x, 3);
    c.erase(3);
    EXPECT_THROW(c.erase(3), std::out_of_range);
    std::size_t n = 0;
    for (auto [slot, lm] : c) { EXPECT_EQ(lm.id, slot); ++n; }
    EXPECT_EQ(n, 999u);
    EXPECT_EQ(c.insert(Landmark{}), 3u);
  }
  EXPECT_EQ(heap.stats().live_nodes, 0);
}
}  // namespace
}  // namespace fastslam::memory
