// PassBlocks against its contract, checked by brute force over particle counts, thread counts,
// grains and the heavy flag: the blocks tile [0, m) in whole lane groups, differ by at most one
// group, and their number follows the documented rules.
#include "engine/internal/pass_blocks.h"

#include <algorithm>

#include <gtest/gtest.h>

namespace fastslam::engine::internal {
namespace {

TEST(PassBlocksTest, BlocksTileTheParticlesInWholeGroups) {
  for (std::size_t m : {1, 7, 8, 9, 100, 128, 129, 1000, 4099}) {
    for (unsigned threads : {1u, 2u, 3u, 8u}) {
      for (std::size_t grain : {1, 16, 128, 512, 100000}) {
        for (bool heavy : {false, true}) {
          const PassBlocks b(m, threads, grain, heavy);
          const std::size_t groups = (m + kMotionLanes - 1) / kMotionLanes;
          ASSERT_GE(b.tasks, 1u);
          ASSERT_LE(b.tasks, groups);
          EXPECT_EQ(b.begin(0), 0u);
          EXPECT_EQ(b.begin(b.tasks), m);
          std::size_t smallest = groups, largest = 0;
          for (std::size_t t = 0; t < b.tasks; ++t) {
            ASSERT_LT(b.begin(t), b.begin(t + 1)) << m << " " << threads << " " << grain;
            EXPECT_EQ(b.begin(t) % kMotionLanes, 0u);
            const std::size_t g =
                (std::min(m, b.begin(t + 1)) - b.begin(t) + kMotionLanes - 1) / kMotionLanes;
            smallest = std::min(smallest, g);
            largest = std::max(largest, g);
          }
          EXPECT_LE(largest - smallest, 1u);
          // The count: ceil(m / grain), at least 4 per thread when heavy, rounded up to a
          // multiple of the threads when above one, at most one per group.
          std::size_t want = (m + grain - 1) / grain;
          if (heavy && threads > 1) want = std::max<std::size_t>(want, 4 * threads);
          if (threads > 1 && want > 1) want = (want + threads - 1) / threads * threads;
          want = std::min(std::max<std::size_t>(want, 1), groups);
          EXPECT_EQ(b.tasks, want) << m << " " << threads << " " << grain << " " << heavy;
        }
      }
    }
  }
}

TEST(PassBlocksTest, ThousandParticlesOnTwoThreads) {
  const PassBlocks b(1000, 2, 128, false);
  ASSERT_EQ(b.tasks, 8u);
  for (std::size_t t = 0; t < b.tasks; ++t) {
    const std::size_t size = b.begin(t + 1) - b.begin(t);
    EXPECT_TRUE(size == 120 || size == 128) << size;
  }
}

TEST(PassBlocksTest, LightSmallPassIsOneBlockHeavyOneIsSplit) {
  EXPECT_EQ(PassBlocks(100, 2, 128, false).tasks, 1u);
  EXPECT_EQ(PassBlocks(100, 2, 128, true).tasks, 8u);
  EXPECT_EQ(PassBlocks(100, 1, 128, true).tasks, 1u);
}

}  // namespace
}  // namespace fastslam::engine::internal
