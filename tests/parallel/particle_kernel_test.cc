// Tests of the per-particle kernel: coverage of every particle exactly once, block shapes that do
// not depend on threads, the thread count honoured, per-thread scratch used by one thread at a
// time, reductions bit-identical for any thread count and grain, exceptions, concurrent callers.
#include "parallel/particle_kernel.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <mutex>
#include <random>
#include <set>
#include <stdexcept>
#include <thread>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/task_arena.h>

namespace fastslam::parallel {
namespace {

// What the concepts accept: const-callable bodies; a mutable lambda (state changed per call,
// which would race) is refused at compile time.
[[maybe_unused]] constexpr auto kGoodBody = [](std::size_t, std::size_t) {};
[[maybe_unused]] constexpr auto kMutableBody = [n = 0](std::size_t, std::size_t) mutable { ++n; };
static_assert(BlockBody<decltype(kGoodBody)>);
static_assert(!BlockBody<decltype(kMutableBody)>);
static_assert(ScratchBlockBody<decltype([](std::size_t, std::size_t, int&) {}), int>);
static_assert(!ScratchBlockBody<decltype([](std::size_t, std::size_t, double*) {}), int>);
static_assert(IndexedBlockBody<decltype([](std::size_t, std::size_t, std::size_t) {})>);
static_assert(BlockMap<decltype([](std::size_t, std::size_t) { return 1.0; }), double>);
static_assert(!BlockMap<decltype([](std::size_t, std::size_t) {}), double>);
static_assert(Combiner<decltype([](double a, double b) { return a + b; }), double>);

constexpr unsigned kThreads[] = {1, 2};
constexpr std::size_t kGrains[] = {1, 3, 64, 256, 1000, 4096, 1 << 20};
constexpr std::size_t kCounts[] = {0, 1, 2, 255, 256, 257, 1000, 4097, 100000};

TEST(ParticleKernel, RejectsBadConfiguration) {
  EXPECT_THROW(ParticleKernel({.threads = 1, .grain = 0}), std::invalid_argument);
  EXPECT_THROW(ParticleKernel({.threads = ParticleKernel::kMaxThreads + 1, .grain = 1}),
               std::invalid_argument);
  const ParticleKernel automatic({.threads = 0, .grain = 16});
  EXPECT_GE(automatic.threads(), 1u);
  EXPECT_EQ(automatic.grain(), 16u);
}

TEST(ParticleKernel, ForEachBlockVisitsEveryParticleOnceInGrainChunks) {
  for (unsigned threads : kThreads) {
    for (std::size_t grain : kGrains) {
      const ParticleKernel kernel({.threads = threads, .grain = grain});
      for (std::size_t count : kCounts) {
        std::vector<std::atomic<int>> visits(count);
        std::mutex mutex;
        std::set<std::pair<std::size_t, std::size_t>> chunks;
        kernel.for_each_block(count, [&](std::size_t begin, std::size_t end) {
          for (std::size_t i = begin; i < end; ++i) {
            visits[i].fetch_add(1);
          }
          std::lock_guard lock(mutex);
          chunks.emplace(begin, end);
        });
        for (std::size_t i = 0; i < count; ++i) {
          ASSERT_EQ(visits[i].load(), 1) << "particle " << i << " count " << count;
        }
        // The chunks are exactly [j * grain, min((j + 1) * grain, count)).
        std::size_t expected_begin = 0;
        for (const auto& [begin, end] : chunks) {
          ASSERT_EQ(begin, expected_begin);
          ASSERT_EQ(end, std::min(count, begin + grain));
          expected_begin = end;
        }
        ASSERT_EQ(expected_begin, count);
      }
    }
  }
}

TEST(ParticleKernel, PerCallGrainOverridesTheKernels) {
  for (unsigned threads : kThreads) {
    const ParticleKernel kernel({.threads = threads, .grain = 1000});
    std::mutex mutex;
    std::set<std::pair<std::size_t, std::size_t>> chunks;
    kernel.for_each_block(
        95,
        [&](std::size_t begin, std::size_t end) {
          std::lock_guard lock(mutex);
          chunks.emplace(begin, end);
        },
        10);
    ASSERT_EQ(chunks.size(), 10u);
    EXPECT_EQ(*chunks.rbegin(), std::make_pair(std::size_t{90}, std::size_t{95}));
    std::atomic<std::size_t> tasks_of_blocks{0};
    kernel.for_each_fixed_block(
        2560, 256, [&](std::size_t, std::size_t, std::size_t) { tasks_of_blocks.fetch_add(1); }, 1);
    EXPECT_EQ(tasks_of_blocks.load(), 10u);
  }
}

TEST(ParticleKernel, ForEachParticleVisitsEveryParticleOnce) {
  for (unsigned threads : kThreads) {
    const ParticleKernel kernel({.threads = threads, .grain = 100});
    std::vector<std::atomic<int>> visits(12345);
    kernel.for_each_particle(visits.size(), [&](std::size_t i) { visits[i].fetch_add(1); });
    for (const auto& v : visits) {
      ASSERT_EQ(v.load(), 1);
    }
  }
}

TEST(ParticleKernel, FixedBlocksDoNotDependOnGrainOrThreads) {
  for (unsigned threads : kThreads) {
    for (std::size_t grain : kGrains) {
      const ParticleKernel kernel({.threads = threads, .grain = grain});
      for (std::size_t block : {1, 7, 256}) {
        const std::size_t count = 3000;
        const std::size_t blocks = (count + block - 1) / block;
        std::vector<std::atomic<int>> seen(blocks);
        kernel.for_each_fixed_block(count, block,
                                    [&](std::size_t b, std::size_t begin, std::size_t end) {
                                      ASSERT_LT(b, blocks);
                                      ASSERT_EQ(begin, b * block);
                                      ASSERT_EQ(end, std::min(count, (b + 1) * block));
                                      seen[b].fetch_add(1);
                                    });
        for (const auto& s : seen) {
          ASSERT_EQ(s.load(), 1);
        }
      }
    }
  }
}

// Runs 64 blocks, each of which waits (until `patience` has passed since the call began) for
// `wanted` blocks to run at once. Returns the largest
// number that ran at once and the number of distinct threads that ran blocks.
std::pair<int, std::size_t> observed_concurrency(const ParticleKernel& kernel, int wanted,
                                                 std::chrono::milliseconds patience) {
  std::atomic<int> running{0}, peak{0};
  std::mutex mutex;
  std::set<std::thread::id> ids;
  const auto deadline = std::chrono::steady_clock::now() + patience;
  kernel.for_each_block(64 * kernel.grain(), [&](std::size_t, std::size_t) {
    const int now = running.fetch_add(1) + 1;
    int seen = peak.load();
    while (now > seen && !peak.compare_exchange_weak(seen, now)) {
    }
    {
      std::lock_guard lock(mutex);
      ids.insert(std::this_thread::get_id());
    }
    while (peak.load() < wanted && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::yield();
    }
    running.fetch_sub(1);
  });
  return {peak.load(), ids.size()};
}

TEST(ParticleKernel, OneThreadRunsOnTheCaller) {
  const ParticleKernel kernel({.threads = 1, .grain = 4});
  const auto caller = std::this_thread::get_id();
  bool all_on_caller = true;
  kernel.for_each_block(1000, [&](std::size_t, std::size_t) {
    if (std::this_thread::get_id() != caller) {
      all_on_caller = false;  // only the caller writes
    }
  });
  EXPECT_TRUE(all_on_caller);
  EXPECT_EQ(observed_concurrency(kernel, 2, std::chrono::milliseconds(50)).first, 1);
}

TEST(ParticleKernel, TwoThreadsRunConcurrentlyAndNoMore) {
  const ParticleKernel kernel({.threads = 2, .grain = 8});
  // A generous deadline, so a busy machine cannot make this flaky: two threads must meet.
  const auto [peak, distinct] = observed_concurrency(kernel, 2, std::chrono::seconds(20));
  EXPECT_EQ(peak, 2);
  EXPECT_EQ(distinct, 2u);
  // Blocks wait a while for a third thread, which a two-thread kernel must never provide.
  const auto [peak3, distinct3] = observed_concurrency(kernel, 3, std::chrono::milliseconds(200));
  EXPECT_EQ(peak3, 2);
  EXPECT_LE(distinct3, 2u);
}

TEST(ParticleKernel, ExecuteRunsInsideTheArena) {
  for (unsigned threads : {1u, 2u}) {
    const ParticleKernel kernel({.threads = threads, .grain = 8});
    const int concurrency = kernel.execute([] { return tbb::this_task_arena::max_concurrency(); });
#if FASTSLAM_PARALLEL_TSAN
    EXPECT_EQ(concurrency, 1);  // TBB algorithms stay on the caller under TSan
#else
    EXPECT_EQ(concurrency, static_cast<int>(threads));
#endif
    // A TBB algorithm inside execute, and the kernel itself nested inside execute.
    std::vector<int> v(10000, 0);
    kernel.execute([&] {
      tbb::parallel_for(std::size_t{0}, v.size(), [&](std::size_t i) { v[i] += 1; });
      kernel.for_each_particle(v.size(), [&](std::size_t i) { v[i] += 2; });
    });
    EXPECT_TRUE(std::all_of(v.begin(), v.end(), [](int x) { return x == 3; }));
  }
}

struct Scratch {
  std::atomic<bool> in_use{false};
  std::vector<double> buffer;
  double total = 0.0;
  int uses = 0;
  Scratch() = default;
  Scratch(const Scratch& other) : buffer(other.buffer), total(other.total), uses(other.uses) {}
};

TEST(ParticleKernel, ScratchIsPerThreadAndSurvivesCalls) {
  for (unsigned threads : kThreads) {
    const ParticleKernel kernel({.threads = threads, .grain = 97});
    ThreadScratch<Scratch> scratch;
    const std::size_t count = 50000;
    std::atomic<int> overlaps{0};
    for (int call = 0; call < 5; ++call) {
      kernel.for_each_block(count, scratch,
                            [&](std::size_t begin, std::size_t end, Scratch& local) {
                              if (local.in_use.exchange(true)) {
                                overlaps.fetch_add(1);
                              }
                              local.buffer.resize(end - begin);  // grows once per thread
                              for (std::size_t i = begin; i < end; ++i) {
                                local.buffer[i - begin] = static_cast<double>(i);
                              }
                              for (double x : local.buffer) {
                                local.total += x;
                              }
                              ++local.uses;
                              local.in_use.store(false);
                            });
    }
    EXPECT_EQ(overlaps.load(), 0);
    double total = 0.0;
    int uses = 0;
    scratch.for_each([&](Scratch& s) {
      total += s.total;
      uses += s.uses;
    });
    const double n = static_cast<double>(count);
    EXPECT_EQ(total, 5.0 * n * (n - 1) / 2);  // exact: every partial sum is an integer < 2^53
    EXPECT_EQ(uses, 5 * static_cast<int>((count + 96) / 97));
    if (threads == 1) {
      EXPECT_EQ(scratch.size(), 1u);
    }
    scratch.clear();
    EXPECT_EQ(scratch.size(), 0u);
  }
}

TEST(ParticleKernel, ScratchCopiesTheExemplar) {
  const ParticleKernel kernel({.threads = 2, .grain = 10});
  ThreadScratch<std::vector<int>> scratch(std::vector<int>(3, 7));
  std::atomic<bool> ok{true};
  kernel.for_each_block(1000, scratch, [&](std::size_t, std::size_t, std::vector<int>& local) {
    if (local.size() != 3 || local[0] != 7) {
      ok = false;
    }
  });
  EXPECT_TRUE(ok.load());
}

// Values whose sum depends on the order of additions (magnitudes from 1e-8 to 1e8).
std::vector<double> order_sensitive_values(std::size_t count) {
  std::mt19937_64 gen(count);
  std::uniform_real_distribution<double> exponent(-8.0, 8.0);
  std::vector<double> v(count);
  for (double& x : v) {
    x = std::pow(10.0, exponent(gen)) * (gen() % 2 == 0 ? 1.0 : -0.999);
  }
  return v;
}

TEST(ParticleKernel, ReduceIsBitIdenticalForAnyThreadsAndGrain) {
  for (std::size_t count : {std::size_t{0}, std::size_t{1}, std::size_t{255}, std::size_t{256},
                            std::size_t{257}, std::size_t{10007}, std::size_t{300000}}) {
    const std::vector<double> v = order_sensitive_values(count);
    // The documented shape, computed here by hand: blocks of kReduceBlock, left fold.
    double expected = 0.0;
    for (std::size_t begin = 0; begin < count; begin += ParticleKernel::kReduceBlock) {
      double block = 0.0;
      for (std::size_t i = begin; i < std::min(count, begin + ParticleKernel::kReduceBlock); ++i) {
        block += v[i];
      }
      expected += block;
    }
    for (unsigned threads : kThreads) {
      for (std::size_t grain : kGrains) {
        const ParticleKernel kernel({.threads = threads, .grain = grain});
        for (int repeat = 0; repeat < 3; ++repeat) {
          const double sum = kernel.reduce(
              count, 0.0,
              [&](std::size_t begin, std::size_t end) {
                double s = 0.0;
                for (std::size_t i = begin; i < end; ++i) {
                  s += v[i];
                }
                return s;
              },
              [](double a, double b) { return a + b; }, repeat == 2 ? grain / 2 + 1 : 0);
          ASSERT_EQ(std::bit_cast<std::uint64_t>(sum), std::bit_cast<std::uint64_t>(expected))
              << "count " << count << " threads " << threads << " grain " << grain;
        }
      }
    }
  }
}

TEST(ParticleKernel, ReduceFoldsInOrderWithNonCommutativeCombine) {
  // Concatenation is associative but not commutative: the fold must keep block order.
  const ParticleKernel kernel({.threads = 2, .grain = 256});
  const std::size_t count = 256 * 40 + 3;
  const std::vector<std::size_t> firsts = kernel.reduce(
      count, std::vector<std::size_t>{},
      [](std::size_t begin, std::size_t) { return std::vector<std::size_t>{begin}; },
      [](const std::vector<std::size_t>& a, const std::vector<std::size_t>& b) {
        std::vector<std::size_t> r = a;
        r.insert(r.end(), b.begin(), b.end());
        return r;
      });
  ASSERT_EQ(firsts.size(), 41u);
  for (std::size_t b = 0; b < firsts.size(); ++b) {
    EXPECT_EQ(firsts[b], b * 256);
  }
}

TEST(ParticleKernel, ExceptionsPropagateAndTheKernelStaysUsable) {
  for (unsigned threads : kThreads) {
    const ParticleKernel kernel({.threads = threads, .grain = 10});
    EXPECT_THROW(kernel.for_each_block(1000,
                                       [](std::size_t begin, std::size_t end) {
                                         if (begin <= 555 && 555 < end) {
                                           throw std::runtime_error("particle 555");
                                         }
                                       }),
                 std::runtime_error);
    EXPECT_THROW(kernel.reduce(
                     1000, 0,
                     [](std::size_t begin, std::size_t) -> int {
                       if (begin == 512) throw std::out_of_range("block 2");
                       return 1;
                     },
                     [](int a, int b) { return a + b; }),
                 std::out_of_range);
    std::atomic<std::size_t> visited{0};
    kernel.for_each_particle(1000, [&](std::size_t) { visited.fetch_add(1); });
    EXPECT_EQ(visited.load(), 1000u);
  }
}

TEST(ParticleKernel, ConcurrentCallersShareOneKernel) {
  const ParticleKernel kernel({.threads = 2, .grain = 64});
  const std::size_t count = 20000;
  std::vector<double> a(count), b(count);
  auto fill = [&](std::vector<double>& v, double value) {
    for (int repeat = 0; repeat < 10; ++repeat) {
      kernel.for_each_particle(count, [&](std::size_t i) { v[i] += value; });
    }
  };
  std::thread other([&] { fill(a, 1.0); });
  fill(b, 2.0);
  other.join();
  EXPECT_TRUE(std::all_of(a.begin(), a.end(), [](double x) { return x == 10.0; }));
  EXPECT_TRUE(std::all_of(b.begin(), b.end(), [](double x) { return x == 20.0; }));
}

TEST(ParticleKernel, MoreThreadsThanCoresStillCoverEverything) {
  const ParticleKernel kernel({.threads = 8, .grain = 16});
  EXPECT_EQ(kernel.threads(), 8u);
  std::vector<std::atomic<int>> visits(5000);
  kernel.for_each_particle(visits.size(), [&](std::size_t i) { visits[i].fetch_add(1); });
  for (const auto& v : visits) {
    ASSERT_EQ(v.load(), 1);
  }
}

}  // namespace
// ---- BackgroundTask -----------------------------------------------------------------------

TEST(BackgroundTask, OneThreadRunsInlineInStart) {
  const ParticleKernel kernel({.threads = 1, .grain = 4});
  BackgroundTask task(kernel);
  std::thread::id ran_on;
  task.start([&] { ran_on = std::this_thread::get_id(); });
  EXPECT_EQ(ran_on, std::this_thread::get_id());  // already done when start returns
  task.wait();
}

TEST(BackgroundTask, StartReturnsBeforeTheTaskEndsAndWaitSeesItsWrites) {
  const ParticleKernel kernel({.threads = 2, .grain = 4});
  BackgroundTask task(kernel);
  std::atomic<bool> released{false};
  bool saw_release = false;  // written by the task, read after wait()
  std::vector<int> written;
  task.start([&] {
    // Run inline in start(), this would wait for a release that start's caller cannot give.
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (!released.load() && std::chrono::steady_clock::now() < deadline) {
      std::this_thread::yield();
    }
    saw_release = released.load();
    written.assign(1000, 7);
  });
  released.store(true);
  task.wait();
  EXPECT_TRUE(saw_release);
  EXPECT_EQ(written, std::vector<int>(1000, 7));
}

TEST(BackgroundTask, StartWaitsForThePreviousTaskAndTheDestructorForTheLast) {
  const ParticleKernel kernel({.threads = 2, .grain = 4});
  long count = 0;  // plain: the tasks must never overlap (TSan checks it)
  bool last_done = false;
  {
    BackgroundTask task(kernel);
    for (int k = 0; k < 200; ++k) task.start([&] { ++count; });
    task.start([&] {
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
      last_done = true;
    });
  }
  EXPECT_EQ(count, 200);
  EXPECT_TRUE(last_done);
}

}  // namespace fastslam::parallel
