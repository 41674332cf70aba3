// The reference count policies of memory/refcount.h: one suite over both (start at one,
// acquire, release reports the last reference exactly once, unique), and the atomic policy under
// many threads acquiring and releasing at once (labelled "concurrency": TSan runs it).
#include "memory/refcount.h"

#include <atomic>
#include <cstddef>

#include <gtest/gtest.h>

#include "tests/memory/heap_fixtures.h"

namespace fastslam::memory {
namespace {

template <class R>
class RefcountTest : public ::testing::Test {};

using Policies = ::testing::Types<AtomicRefcount, LocalRefcount>;
TYPED_TEST_SUITE(RefcountTest, Policies);

TYPED_TEST(RefcountTest, CountsReferencesAndReportsTheLastRelease) {
  TypeParam refs;
  EXPECT_TRUE(refs.unique());
  refs.acquire();
  refs.acquire();
  EXPECT_FALSE(refs.unique());
  EXPECT_FALSE(refs.release());
  EXPECT_FALSE(refs.unique());
  EXPECT_FALSE(refs.release());
  EXPECT_TRUE(refs.unique());
  EXPECT_TRUE(refs.release());
}

TEST(AtomicRefcount, ConcurrentAcquiresAndReleasesLeaveOneLastRelease) {
  constexpr std::size_t kTasks = 8;
  const int rounds = testing::sized(200000, 20000);
  AtomicRefcount refs;
  std::atomic<int> last{0};
  testing::run_tasks(kTasks, 4, [&](std::size_t) {
    for (int i = 0; i < rounds; ++i) {
      refs.acquire();
      if (refs.release()) last.fetch_add(1);
    }
  });
  EXPECT_EQ(last.load(), 0);  // the initial reference was held throughout
  EXPECT_TRUE(refs.unique());
  // Every holder releases: exactly one sees the count reach zero.
  for (std::size_t i = 0; i < kTasks - 1; ++i) refs.acquire();
  testing::run_tasks(kTasks, 4, [&](std::size_t) {
    if (refs.release()) last.fetch_add(1);
  });
  EXPECT_EQ(last.load(), 1);
}

}  // namespace
}  // namespace fastslam::memory
