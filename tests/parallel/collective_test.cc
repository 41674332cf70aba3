// parallel/collective.h: the shares against a brute-force deal of blocks, the owner against the
// shares, LocalGroup's two primitives against what each rank sent, and shared_reduce against
// one process's kernel.reduce, bit for bit.
#include "parallel/collective.h"

#include <bit>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::parallel {
namespace {

constexpr std::size_t kBlock = ParticleKernel::kReduceBlock;

// Runs body(rank, collective) on `ranks` threads.
template <class Body>
void on_ranks(int ranks, const Body& body) {
  LocalGroup group(ranks);
  std::vector<std::thread> threads;
  for (int r = 0; r < ranks; ++r) {
    threads.emplace_back([&, r, member = group.member(r)] { body(r, *member); });
  }
  for (std::thread& t : threads) t.join();
}

TEST(ParticleShareTest, WholeBlocksDealtEvenlyInOrder) {
  for (const std::size_t total : {1ul, 255ul, 256ul, 257ul, 1000ul, 4096ul, 100003ul}) {
    const std::size_t blocks = (total + kBlock - 1) / kBlock;
    for (int ranks = 1; ranks <= 7; ++ranks) {
      SCOPED_TRACE(std::to_string(total) + " particles, " + std::to_string(ranks) + " ranks");
      if (blocks < static_cast<std::size_t>(ranks)) {
        EXPECT_THROW(particle_share(total, ranks, 0), std::invalid_argument);
        continue;
      }
      std::size_t next = 0, fewest = blocks, most = 0;
      for (int r = 0; r < ranks; ++r) {
        const ParticleShare s = particle_share(total, ranks, r);
        EXPECT_EQ(s.first, next);
        EXPECT_EQ(s.first % kBlock, 0u);
        EXPECT_GT(s.count, 0u);
        const std::size_t b = (s.count + kBlock - 1) / kBlock;
        fewest = std::min(fewest, b);
        most = std::max(most, b);
        for (std::size_t i = s.first; i < s.first + s.count; i += 97) {
          EXPECT_EQ(particle_owner(i, total, ranks), r) << "particle " << i;
        }
        EXPECT_EQ(particle_owner(s.first + s.count - 1, total, ranks), r);
        next = s.first + s.count;
      }
      EXPECT_EQ(next, total);
      EXPECT_LE(most - fewest, 1u);
    }
  }
}

TEST(LocalGroupTest, AllGatherAndExchangeDeliverWhatEachRankSent) {
  constexpr int kRanks = 4;
  on_ranks(kRanks, [&](int r, Collective& c) {
    EXPECT_EQ(c.rank(), r);
    EXPECT_EQ(c.size(), kRanks);
    // Rank r contributes r bytes of value r (rank 0 nothing).
    const Bytes mine(static_cast<std::size_t>(r), std::byte(r));
    std::vector<std::size_t> sizes;
    const Bytes all = c.all_gather(mine, &sizes);
    ASSERT_EQ(sizes, (std::vector<std::size_t>{0, 1, 2, 3}));
    const Bytes want = {std::byte(1), std::byte(2), std::byte(2),
                        std::byte(3), std::byte(3), std::byte(3)};
    EXPECT_EQ(all, want);
    // Rank s sends d + 1 bytes of value 16 s + d to rank d.
    std::vector<Bytes> to(kRanks);
    for (int d = 0; d < kRanks; ++d) to[d].assign(d + 1, std::byte(16 * r + d));
    const std::vector<Bytes> from = c.exchange(to);
    for (int s = 0; s < kRanks; ++s) {
      if (s == r) {
        EXPECT_TRUE(from[s].empty());
      } else {
        EXPECT_EQ(from[s], Bytes(static_cast<std::size_t>(r + 1), std::byte(16 * s + r)));
      }
    }
    EXPECT_THROW(c.exchange({}), std::invalid_argument);
  });
}

TEST(SharedReduceTest, EveryRankGetsTheOneProcessBits) {
  constexpr std::size_t kTotal = 1800;
  std::vector<double> values(kTotal);
  for (std::size_t i = 0; i < kTotal; ++i) values[i] = std::sin(0.37 * i) * std::exp(i % 13);
  const ParticleKernel one({1, 64});
  auto add = [](double a, double b) { return a + b; };
  auto sum_over = [&](std::size_t offset) {
    return [&, offset](std::size_t begin, std::size_t end) {
      double s = 0.0;
      for (std::size_t i = begin; i < end; ++i) s += values[offset + i];
      return s;
    };
  };
  const double want = one.reduce(kTotal, 0.0, sum_over(0), add);
  for (int ranks = 1; ranks <= 5; ++ranks) {
    on_ranks(ranks, [&](int r, Collective& c) {
      const ParticleShare share = particle_share(kTotal, ranks, r);
      const ParticleKernel kernel({2, 64});
      const double got = shared_reduce(kernel, &c, share.count, 0.0, sum_over(share.first), add);
      EXPECT_EQ(std::bit_cast<std::uint64_t>(got), std::bit_cast<std::uint64_t>(want))
          << ranks << " ranks, rank " << r;
    });
  }
}

}  // namespace
}  // namespace fastslam::parallel
