// Tests of parallel/random_stream.h: Philox against Random123's known answers, the documented key
// layout and draw conversions, determinism (batch == scalar for any blocking; identical under
// TBB with any grain, partitioner and thread count), the accuracy of the Box-Muller kernel
// against long-double libm, and statistics with fixed seeds.
//
// Statistical bounds: every check is a two-sided test at about 5 standard deviations (or a
// tail probability below 1e-4 for KS and chi-square), so with any seed a correct generator fails
// one of them with probability well under 1e-3, while the defects they target (a bad mixer,
// correlated keys, a biased transform) move the statistic by far more at these sample sizes.
// The seeds are fixed, so the run is deterministic. Draw counts are a few million in optimised
// builds and smaller in debug and sanitizer builds (the bounds scale with the count).
#include "parallel/random_stream.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <iostream>
#include <span>
#include <vector>

#include <gtest/gtest.h>
#include <oneapi/tbb/blocked_range.h>
#include <oneapi/tbb/parallel_for.h>
#include <oneapi/tbb/partitioner.h>
#include <oneapi/tbb/task_arena.h>

#include "parallel/internal/philox.h"
#include "parallel/internal/thread_fork_join.h"

#if defined(__SANITIZE_THREAD__)
#define FASTSLAM_TEST_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define FASTSLAM_TEST_TSAN 1
#endif
#endif
#if defined(__SANITIZE_ADDRESS__) || defined(FASTSLAM_TEST_TSAN)
#define FASTSLAM_TEST_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define FASTSLAM_TEST_SANITIZED 1
#endif
#endif

namespace fastslam::parallel {
namespace {

using internal::philox4x32_10;
using internal::PhiloxCounter;
using internal::PhiloxKey;

#if defined(FASTSLAM_TEST_SANITIZED) || !defined(NDEBUG)
constexpr std::size_t kStatDraws = std::size_t{1} << 19;  // debug and sanitizer builds
#else
constexpr std::size_t kStatDraws = std::size_t{1} << 22;  // ~4.2 million
#endif
constexpr double kSigmas = 5.0;

bool same_bits(std::span<const double> a, std::span<const double> b) {
  return a.size() == b.size() &&
         (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0);
}

// ----------------------------------------------------------------------------------------------
// Philox4x32-10.

struct Kat {
  PhiloxCounter ctr;
  PhiloxKey key;
  PhiloxCounter expected;
};
// Random123's kat_vectors for philox4x32 with 10 rounds (zero, all-ones, digits of pi).
constexpr std::array<Kat, 3> kKats = {{
    {{0, 0, 0, 0}, {0, 0}, {0x6627e8d5u, 0xe169c58du, 0xbc57ac4cu, 0x9b00dbd8u}},
    {{0xffffffffu, 0xffffffffu, 0xffffffffu, 0xffffffffu},
     {0xffffffffu, 0xffffffffu},
     {0x408f276du, 0x41c83b0eu, 0xa20bc7c6u, 0x6d5451fdu}},
    {{0x243f6a88u, 0x85a308d3u, 0x13198a2eu, 0x03707344u},
     {0xa4093822u, 0x299f31d0u},
     {0xd16cfe09u, 0x94fdccebu, 0x5001e420u, 0x24126ea1u}},
}};

TEST(Philox4x32x10, MatchesRandom123KnownAnswers) {
  for (const Kat& kat : kKats) EXPECT_EQ(philox4x32_10(kat.ctr, kat.key), kat.expected);
}

template <std::size_t L>
void expect_lanes_match_scalar(PhiloxKey key, std::uint32_t c2, std::uint32_t c3,
                               std::uint32_t salt) {
  internal::PhiloxLanes<L> lanes{};
  std::array<PhiloxCounter, L> counters{};
  for (std::size_t l = 0; l < L; ++l) {
    counters[l] = {static_cast<std::uint32_t>(l * 0x9E3779B9u + salt),
                   static_cast<std::uint32_t>(salt ^ (l << 7)), c2, c3};
    lanes.x0[l] = counters[l][0];
    lanes.x1[l] = counters[l][1];
  }
  internal::philox4x32_10_lanes(key, c2, c3, lanes);
  for (std::size_t l = 0; l < L; ++l) {
    const PhiloxCounter want = philox4x32_10(counters[l], key);
    EXPECT_EQ(lanes.x0[l], want[0]) << "lane " << l;
    EXPECT_EQ(lanes.x1[l], want[1]) << "lane " << l;
    EXPECT_EQ(lanes.x2[l], want[2]) << "lane " << l;
    EXPECT_EQ(lanes.x3[l], want[3]) << "lane " << l;
  }
}

TEST(Philox4x32x10, LanesMatchScalar) {
  for (const Kat& kat : kKats) {  // lane 0 of each run is a known-answer counter
    internal::PhiloxLanes<4> lanes{};
    for (std::size_t l = 0; l < 4; ++l) {
      lanes.x0[l] = kat.ctr[0] + static_cast<std::uint32_t>(l);
      lanes.x1[l] = kat.ctr[1];
    }
    internal::philox4x32_10_lanes(kat.key, kat.ctr[2], kat.ctr[3], lanes);
    EXPECT_EQ(
        (PhiloxCounter{
            static_cast<std::uint32_t>(lanes.x0[0]), static_cast<std::uint32_t>(lanes.x1[0]),
            static_cast<std::uint32_t>(lanes.x2[0]), static_cast<std::uint32_t>(lanes.x3[0])}),
        kat.expected);
  }
  for (std::uint32_t salt : {0u, 1u, 0xdeadbeefu, 0xffffffffu}) {
    expect_lanes_match_scalar<1>({salt, ~salt}, 7, 0xff000000u, salt);
    expect_lanes_match_scalar<4>({0xffffffffu, 0}, salt, ~salt, salt);
    expect_lanes_match_scalar<16>({salt * 3u, salt + 1u}, 0xffffffffu, salt, salt);
  }
}

// The explicit SIMD rounds (AVX-512 and AVX2 builds; the portable fallback elsewhere) against
// the scalar block, every counter word varied, extreme words included.
template <std::size_t kL>
void expect_simd_rounds_match_scalar() {
  for (std::uint32_t salt :
       {0u, 1u, 0x80000000u, 0xdeadbeefu, 0xffffffffu, 0x12345678u, 0x7fffffffu, 0xfffffffeu}) {
    const PhiloxKey key{salt * 7u + 3u, ~salt};
    const internal::PhiloxRoundKeys keys = internal::philox_round_keys(key);
    std::uint64_t x[4][kL];
    std::array<PhiloxCounter, kL> counters{};
    for (std::size_t l = 0; l < kL; ++l) {
      counters[l] = {static_cast<std::uint32_t>(l * 0x9E3779B9u + salt),
                     l % 3 == 0 ? 0xffffffffu : static_cast<std::uint32_t>(salt ^ (l << 9)),
                     static_cast<std::uint32_t>(~salt + l), l % 5 == 0 ? 0u : salt * 31u};
      for (int w = 0; w < 4; ++w) x[w][l] = counters[l][w];
    }
    internal::philox4x32_10_simd<kL>(keys, x[0], x[1], x[2], x[3]);
    for (std::size_t l = 0; l < kL; ++l) {
      const PhiloxCounter want = philox4x32_10(counters[l], key);
      for (int w = 0; w < 4; ++w) EXPECT_EQ(x[w][l], want[w]) << "salt " << salt << " lane " << l;
    }
  }
}

// The explicit SIMD rounds at several widths (AVX-512: pairs of vectors and a single one).
TEST(Philox4x32x10, SimdRoundsMatchScalar) {
  expect_simd_rounds_match_scalar<16>();
  expect_simd_rounds_match_scalar<8>();  // widths are multiples of every kPhiloxSimdStep
  expect_simd_rounds_match_scalar<24>();
  expect_simd_rounds_match_scalar<32>();
  std::cout << "SIMD lanes in this build: " << internal::kPhiloxSimdLanes << "\n";
}

// ----------------------------------------------------------------------------------------------
// Key layout and draw conversions.

TEST(RandomStream, WordsFollowTheDocumentedKeyLayout) {
  const StreamKey key{.seed = 0x0123456789abcdefu,
                      .step = (std::uint64_t{0xabcdef} << 32) | 0x13579bdfu,
                      .particle = 4242,
                      .purpose = Purpose::kProposal};
  RandomStream stream(key);
  const PhiloxKey philox_key = {0x89abcdefu, 0x01234567u};
  for (std::uint32_t block = 0; block < 40; ++block) {
    const PhiloxCounter want =
        philox4x32_10({block, 4242u, 0x13579bdfu, (2u << 24) | 0xabcdefu}, philox_key);
    for (std::uint32_t w : want) EXPECT_EQ(stream.next_u32(), w) << "block " << block;
  }
  EXPECT_EQ(stream.words_drawn(), 160u);
}

TEST(RandomStream, DrawConversions) {
  const StreamKey key{.seed = 99, .step = 3, .particle = 5, .purpose = Purpose::kResample};
  RandomStream words(key);
  RandomStream u64s(key);
  RandomStream uniforms(key);
  RandomStream positives(key);
  for (int i = 0; i < 1000; ++i) {
    const std::uint64_t low = words.next_u32();
    const std::uint64_t high = words.next_u32();
    const std::uint64_t bits = low | high << 32;
    EXPECT_EQ(u64s.next_u64(), bits);
    EXPECT_EQ(uniforms.uniform(), static_cast<double>(bits >> 11) * 0x1p-53);
    EXPECT_EQ(positives.uniform_pos(), static_cast<double>((bits >> 11) | 1u) * 0x1p-53);
  }
  // The extremes of the conversions: uniform() never reaches 1, uniform_pos() never 0 or 1.
  EXPECT_EQ(uniform_from_bits(0), 0.0);
  EXPECT_LT(uniform_from_bits(~std::uint64_t{0}), 1.0);
  EXPECT_EQ(uniform_from_bits(~std::uint64_t{0}), 1.0 - 0x1p-53);
  EXPECT_EQ(uniform_pos_from_bits(0), 0x1p-53);
  EXPECT_EQ(uniform_pos_from_bits(~std::uint64_t{0}), 1.0 - 0x1p-53);
  EXPECT_EQ(uniform_pos_from_bits(std::uint64_t{1} << 63), 0.5 + 0x1p-53);
}

TEST(RandomStream, NormalIsTheBoxMullerPairOfTwoU64Draws) {
  const StreamKey key{.seed = 7, .step = 11, .particle = 13, .purpose = Purpose::kMotion};
  RandomStream bits(key);
  RandomStream normals(key);
  for (int i = 0; i < 1000; ++i) {
    const std::uint64_t a = bits.next_u64();
    const std::uint64_t b = bits.next_u64();
    const std::array<double, 2> z = normal_pair_from_bits(a, b);
    EXPECT_EQ(normals.normal(), z[0]);
    EXPECT_EQ(normals.normal(), z[1]);
  }
}

// Mixed draws: a normal() pair draws four words whether or not the pair was precomputed, and the
// spare does not draw any.
TEST(RandomStream, MixedDrawsShareOneWordSequence) {
  const StreamKey key{.seed = 1, .step = 2, .particle = 3, .purpose = Purpose::kUser};
  RandomStream stream(key);
  RandomStream bits(key);
  for (int round = 0; round < 200; ++round) {
    switch (round % 5) {
      case 0: {  // normal pair on a block boundary (precomputed) or off it
        const std::uint64_t a = bits.next_u64();
        const std::uint64_t b = bits.next_u64();
        const auto z = normal_pair_from_bits(a, b);
        EXPECT_EQ(stream.normal(), z[0]) << round;
        EXPECT_EQ(stream.normal(), z[1]) << round;
        break;
      }
      case 1:
        EXPECT_EQ(stream.uniform(), uniform_from_bits(bits.next_u64())) << round;
        break;
      case 2:
        EXPECT_EQ(stream.next_u32(), bits.next_u32()) << round;
        break;
      case 3: {  // a lone normal(): its spare is returned after the next draws
        const std::uint64_t a = bits.next_u64();
        const std::uint64_t b = bits.next_u64();
        const auto z = normal_pair_from_bits(a, b);
        EXPECT_EQ(stream.normal(), z[0]) << round;
        EXPECT_EQ(stream.uniform_pos(), uniform_pos_from_bits(bits.next_u64())) << round;
        EXPECT_EQ(stream.normal(), z[1]) << round;
        break;
      }
      default:
        EXPECT_EQ(stream.next_u64(), bits.next_u64()) << round;
        break;
    }
    EXPECT_EQ(stream.words_drawn(), bits.words_drawn()) << round;
  }
}

// The transform against long-double libm: radius sqrt(-2 ln u1) and angle 2 pi t, including the
// extreme draws (u1 = 2^-53 and 1, every octant boundary of t).
TEST(RandomStream, BoxMullerMatchesLongDoubleLibm) {
  const auto check = [](std::uint64_t a, std::uint64_t b) {
    const std::array<double, 2> z = normal_pair_from_bits(a, b);
    const long double u1 = static_cast<long double>((a >> 11) + 1) * 0x1p-53L;
    const long double t = static_cast<long double>(b >> 11) * 0x1p-53L;
    const long double pi = 3.141592653589793238462643383279502884L;
    const long double r = std::sqrt(-2.0L * std::log(u1));
    const long double z0 = r * std::cos(2.0L * pi * t);
    const long double z1 = r * std::sin(2.0L * pi * t);
    // A few ulp of the radius: log, sqrt and sin/cos are each within ~1-2 ulp.
    const double tolerance = 8.0 * 0x1p-52 * static_cast<double>(std::max(r, 1.0L));
    EXPECT_NEAR(z[0], static_cast<double>(z0), tolerance) << a << ' ' << b;
    EXPECT_NEAR(z[1], static_cast<double>(z1), tolerance) << a << ' ' << b;
    EXPECT_TRUE(std::isfinite(z[0]) && std::isfinite(z[1]));
  };
  const std::uint64_t top = ~std::uint64_t{0};
  for (std::uint64_t a : {std::uint64_t{0}, std::uint64_t{1} << 11, std::uint64_t{2} << 11,
                          std::uint64_t{1} << 63, top - (std::uint64_t{1} << 11), top}) {
    for (std::uint64_t eighth = 0; eighth < 8; ++eighth) {
      const std::uint64_t b = eighth << 61;  // t = eighth / 8
      check(a, b);
      check(a, b + (std::uint64_t{1} << 11));
      check(a, b - (std::uint64_t{1} << 11));
    }
  }
  // u1 = 2^-53 gives the largest radius, sqrt(106 ln 2) = 8.57...; u1 = 1 gives 0.
  EXPECT_NEAR(normal_pair_from_bits(0, 0)[0], std::sqrt(106.0 * std::log(2.0)), 1e-14);
  EXPECT_EQ(normal_pair_from_bits(top, 0)[0], 0.0);
  RandomStream stream({.seed = 2024, .step = 0, .particle = 0, .purpose = Purpose::kUser});
  for (std::size_t i = 0; i < kStatDraws / 16; ++i) {
    const std::uint64_t a = stream.next_u64();
    check(a, stream.next_u64());
  }
}

// ----------------------------------------------------------------------------------------------
// Determinism.

TEST(RandomStream, SameKeySameSequenceAndCopiesContinueIdentically) {
  const StreamKey key{.seed = 5, .step = 6, .particle = 7, .purpose = Purpose::kAssociation};
  RandomStream a(key);
  RandomStream b(key);
  for (int i = 0; i < 100; ++i) {
    EXPECT_EQ(a.normal(), b.normal());
    EXPECT_EQ(a.uniform(), b.uniform());
    EXPECT_EQ(a.next_u32(), b.next_u32());
  }
  RandomStream c = a;
  for (int i = 0; i < 100; ++i) {
    EXPECT_EQ(a.normal(), c.normal());
    EXPECT_EQ(a.uniform(), c.uniform());
  }
}

TEST(RandomStream, EveryKeyFieldChangesTheStream) {
  const StreamKey base{.seed = 10, .step = 20, .particle = 30, .purpose = Purpose::kMotion};
  std::vector<StreamKey> keys = {base};
  for (StreamKey k :
       {StreamKey{11, 20, 30, Purpose::kMotion}, StreamKey{10, 21, 30, Purpose::kMotion},
        StreamKey{10, 20 + (std::uint64_t{1} << 32), 30, Purpose::kMotion},
        StreamKey{10 + (std::uint64_t{1} << 32), 20, 30, Purpose::kMotion},
        StreamKey{10, 20, 31, Purpose::kMotion}, StreamKey{10, 20, 30, Purpose::kProposal},
        StreamKey{10, 20, 30, Purpose::kUser}}) {
    keys.push_back(k);
  }
  std::vector<std::uint64_t> firsts;
  firsts.reserve(keys.size());
  for (const StreamKey& k : keys) firsts.push_back(RandomStream(k).next_u64());
  std::sort(firsts.begin(), firsts.end());
  EXPECT_EQ(std::adjacent_find(firsts.begin(), firsts.end()), firsts.end());
}

// normals_for_particles / uniforms_for_particles == per-particle scalar streams, for any
// per_particle and any split of the particles into calls.
TEST(RandomStream, BatchesEqualScalarStreamsForAnyBlocking) {
  const std::uint64_t seed = 0xfeedfacecafebeefu;
  const std::uint64_t step = (std::uint64_t{1} << 40) + 17;
  const std::uint32_t first = 1000;
  for (std::size_t per_particle : {1u, 2u, 3u, 4u, 5u, 7u, 16u, 33u}) {
    for (std::size_t count : {1u, 3u, 17u, 101u}) {
      std::vector<double> normals(count * per_particle);
      std::vector<double> uniforms(count * per_particle);
      normals_for_particles(seed, step, Purpose::kMotion, first, count, per_particle, normals);
      uniforms_for_particles(seed, step, Purpose::kResample, first, count, per_particle, uniforms);
      for (std::size_t k = 0; k < count; ++k) {
        const auto particle = static_cast<std::uint32_t>(first + k);
        RandomStream n({seed, step, particle, Purpose::kMotion});
        RandomStream u({seed, step, particle, Purpose::kResample});
        for (std::size_t j = 0; j < per_particle; ++j) {
          ASSERT_EQ(normals[k * per_particle + j], n.normal())
              << "P=" << per_particle << " count=" << count << " k=" << k << " j=" << j;
          ASSERT_EQ(uniforms[k * per_particle + j], u.uniform())
              << "P=" << per_particle << " count=" << count << " k=" << k << " j=" << j;
        }
      }
      for (std::size_t block : {1u, 2u, 3u, 5u, 16u, 17u, 64u}) {
        std::vector<double> split_normals(count * per_particle);
        std::vector<double> split_uniforms(count * per_particle);
        for (std::size_t k = 0; k < count; k += block) {
          const std::size_t n = std::min(block, count - k);
          const auto p = static_cast<std::uint32_t>(first + k);
          normals_for_particles(
              seed, step, Purpose::kMotion, p, n, per_particle,
              std::span(split_normals).subspan(k * per_particle, n * per_particle));
          uniforms_for_particles(
              seed, step, Purpose::kResample, p, n, per_particle,
              std::span(split_uniforms).subspan(k * per_particle, n * per_particle));
        }
        EXPECT_TRUE(same_bits(split_normals, normals))
            << "P=" << per_particle << " block=" << block;
        EXPECT_TRUE(same_bits(split_uniforms, uniforms))
            << "P=" << per_particle << " block=" << block;
      }
    }
  }
  normals_for_particles(seed, step, Purpose::kMotion, first, 0, 3, {});  // empty batches
  normals_for_particles(seed, step, Purpose::kMotion, first, 5, 0, {});
}

// normal_pairs_for_particles == the first two normals of per-particle scalar streams (and so
// the interleaved normals_for_particles(..., 2, ...)), for any split into calls, including
// particle numbers near 2^32.
TEST(RandomStream, NormalPairsEqualScalarStreamsForAnyBlocking) {
  const std::uint64_t seed = 0x0123456789abcdefu;
  const std::uint64_t step = 123456789;
  for (const std::uint32_t first : {0u, 1000u, 0xFFFFFFFFu - 200u}) {
    for (std::size_t count : {1u, 3u, 16u, 17u, 101u, 200u}) {
      std::vector<double> a(count);
      std::vector<double> b(count);
      normal_pairs_for_particles(seed, step, Purpose::kMotion, first, count, a, b);
      std::vector<double> interleaved(2 * count);
      normals_for_particles(seed, step, Purpose::kMotion, first, count, 2, interleaved);
      for (std::size_t k = 0; k < count; ++k) {
        RandomStream n({seed, step, static_cast<std::uint32_t>(first + k), Purpose::kMotion});
        const double z0 = n.normal();
        const double z1 = n.normal();
        ASSERT_EQ(a[k], z0) << "first=" << first << " count=" << count << " k=" << k;
        ASSERT_EQ(b[k], z1) << "first=" << first << " count=" << count << " k=" << k;
        ASSERT_EQ(interleaved[2 * k], z0);
        ASSERT_EQ(interleaved[2 * k + 1], z1);
      }
      for (std::size_t block : {1u, 5u, 16u, 33u}) {
        std::vector<double> split_a(count);
        std::vector<double> split_b(count);
        for (std::size_t k = 0; k < count; k += block) {
          const std::size_t n = std::min(block, count - k);
          normal_pairs_for_particles(
              seed, step, Purpose::kMotion, static_cast<std::uint32_t>(first + k), n,
              std::span(split_a).subspan(k, n), std::span(split_b).subspan(k, n));
        }
        EXPECT_TRUE(same_bits(split_a, a)) << "block=" << block;
        EXPECT_TRUE(same_bits(split_b, b)) << "block=" << block;
      }
    }
  }
  normal_pairs_for_particles(seed, step, Purpose::kMotion, 0, 0, {}, {});  // empty batch
}

// normal_pairs_for_particles over several steps == Box-Muller on the scalar reference block
// (philox4x32_10 of counter {0, particle, step low, purpose | step high}), for every count up to
// 80 (whole SIMD chunks of 32 and 8 lanes and every remainder), keys and steps with extreme
// words, first particles next to 2^32 (counter word 1 wraps) and a stride past the count.
TEST(RandomStream, NormalPairsEqualScalarReferenceOverManyLanesAndKeys) {
  const std::array<std::uint64_t, 4> steps = {0, 0xFFFFFFFFu, (std::uint64_t{0xFFFFFF} << 32) | 7,
                                              123456789};
  for (const std::uint64_t seed : {std::uint64_t{0}, ~std::uint64_t{0}, 0x0123456789abcdefu}) {
    const PhiloxKey key = {static_cast<std::uint32_t>(seed),
                           static_cast<std::uint32_t>(seed >> 32)};
    for (const std::uint32_t first : {0u, 5u, 0xFFFFFFFFu - 90u}) {
      for (std::size_t count = 1; count <= 80; ++count) {
        if (std::uint64_t{first} + count > (std::uint64_t{1} << 32)) continue;
        const std::size_t stride = count + 3;
        std::vector<double> z0(steps.size() * stride, -7.0);
        std::vector<double> z1(steps.size() * stride, -7.0);
        normal_pairs_for_particles(seed, steps, Purpose::kMotion, first, count, z0, z1, stride);
        for (std::size_t j = 0; j < steps.size(); ++j) {
          const auto c2 = static_cast<std::uint32_t>(steps[j]);
          const auto c3 = (static_cast<std::uint32_t>(Purpose::kMotion) << 24) |
                          static_cast<std::uint32_t>(steps[j] >> 32);
          for (std::size_t k = 0; k < stride; ++k) {
            if (k >= count) {  // past the count: untouched
              ASSERT_EQ(z0[j * stride + k], -7.0);
              ASSERT_EQ(z1[j * stride + k], -7.0);
              continue;
            }
            const PhiloxCounter w =
                philox4x32_10({0, static_cast<std::uint32_t>(first + k), c2, c3}, key);
            const std::array<double, 2> want = normal_pair_from_bits(
                w[0] | std::uint64_t{w[1]} << 32, w[2] | std::uint64_t{w[3]} << 32);
            ASSERT_EQ(std::bit_cast<std::uint64_t>(z0[j * stride + k]),
                      std::bit_cast<std::uint64_t>(want[0]))
                << "seed " << seed << " first " << first << " count " << count << " step "
                << steps[j] << " k " << k;
            ASSERT_EQ(std::bit_cast<std::uint64_t>(z1[j * stride + k]),
                      std::bit_cast<std::uint64_t>(want[1]))
                << "seed " << seed << " first " << first << " count " << count << " step "
                << steps[j] << " k " << k;
          }
        }
      }
    }
  }
}

// fill_normal / fill_uniform == repeated scalar calls, from any position, and the stream draws
// the same values afterwards.
TEST(RandomStream, FillsEqualRepeatedScalarCalls) {
  const StreamKey key{.seed = 77, .step = 8, .particle = 9, .purpose = Purpose::kSimulator};
  // Draws made before the fill: none, a lone normal (spare pending), whole pairs, one uniform
  // (half a block), odd word counts (off a block boundary for good), a full buffer.
  const std::vector<std::vector<int>> preludes = {{},
                                                  {0},
                                                  {0, 0},
                                                  {0, 0, 0, 0, 0, 0, 0, 0, 0, 0},
                                                  {1},
                                                  {1, 1},
                                                  {2},
                                                  {2, 2, 2},
                                                  {2, 0},
                                                  {1, 0},
                                                  {2, 2, 2, 2, 2, 2, 2, 2, 2, 2, 2, 2, 2, 2, 2, 2}};
  const auto draw = [](RandomStream& s, int kind) {
    if (kind == 0) return s.normal();
    if (kind == 1) return s.uniform();
    return static_cast<double>(s.next_u32());
  };
  for (const auto& prelude : preludes) {
    for (std::size_t n : {0u, 1u, 2u, 3u, 7u, 8u, 9u, 31u, 32u, 33u, 65u, 1000u}) {
      for (int fill_normals = 0; fill_normals < 2; ++fill_normals) {
        RandomStream filled(key);
        RandomStream scalar(key);
        for (int kind : prelude) EXPECT_EQ(draw(filled, kind), draw(scalar, kind));
        std::vector<double> got(n);
        std::vector<double> want(n);
        if (fill_normals != 0) {
          filled.fill_normal(got);
          for (double& v : want) v = scalar.normal();
        } else {
          filled.fill_uniform(got);
          for (double& v : want) v = scalar.uniform();
        }
        EXPECT_TRUE(same_bits(got, want)) << "n=" << n << " normals=" << fill_normals;
        EXPECT_EQ(filled.words_drawn(), scalar.words_drawn());
        for (int kind : {0, 1, 2, 0, 0, 1}) EXPECT_EQ(draw(filled, kind), draw(scalar, kind));
      }
    }
  }
}

// The engine-like use: every particle's motion normals and its resampling uniform, computed by
// tasks over blocks of particles.
constexpr std::uint64_t kThreadSeed = 0x1234;
constexpr std::size_t kThreadParticles = 5000;
constexpr std::size_t kThreadPerParticle = 3;

void compute_block(std::size_t begin, std::size_t end, std::uint64_t step,
                   std::vector<double>& normals, std::vector<double>& uniforms) {
  const std::size_t n = end - begin;
  normals_for_particles(
      kThreadSeed, step, Purpose::kMotion, static_cast<std::uint32_t>(begin), n, kThreadPerParticle,
      std::span(normals).subspan(begin * kThreadPerParticle, n * kThreadPerParticle));
  for (std::size_t k = begin; k < end; ++k) {  // scalar streams built inside the task
    RandomStream stream({kThreadSeed, step, static_cast<std::uint32_t>(k), Purpose::kResample});
    uniforms[k] = stream.uniform();
  }
}

struct Outputs {
  std::vector<double> normals = std::vector<double>(kThreadParticles * kThreadPerParticle);
  std::vector<double> uniforms = std::vector<double>(kThreadParticles);
};

Outputs serial_outputs(std::uint64_t step) {
  Outputs out;
  compute_block(0, kThreadParticles, step, out.normals, out.uniforms);
  return out;
}

// Plain std::threads (the scheduler of TSan builds): 1, 2 and 4 threads, several block sizes.
TEST(RandomStreamThreads, IdenticalOnAnyNumberOfThreadsAndBlockSize) {
  const std::uint64_t step = 42;
  const Outputs want = serial_outputs(step);
  for (unsigned threads : {1u, 2u, 4u}) {
    for (std::size_t block :
         {std::size_t{1}, std::size_t{7}, std::size_t{64}, std::size_t{1000}, kThreadParticles}) {
      Outputs got;
      const std::size_t blocks = (kThreadParticles + block - 1) / block;
      internal::thread_fork_join(threads, blocks, [&](std::size_t b) {
        compute_block(b * block, std::min(kThreadParticles, (b + 1) * block), step, got.normals,
                      got.uniforms);
      });
      EXPECT_TRUE(same_bits(got.normals, want.normals)) << threads << " threads, block " << block;
      EXPECT_TRUE(same_bits(got.uniforms, want.uniforms)) << threads << " threads, block " << block;
    }
  }
}

#if !defined(FASTSLAM_TEST_TSAN)
// TBB: grain sizes, partitioners, arenas of 1 and 2 threads. Not under TSan: Debian's libtbb is
// not instrumented, so TSan reports TBB's task hand-offs as races (see thread_fork_join.h).
TEST(RandomStreamThreads, IdenticalUnderTbbForAnyGrainPartitionerAndArena) {
  const std::uint64_t step = 43;
  const Outputs want = serial_outputs(step);
  for (int threads : {1, 2}) {
    tbb::task_arena arena(threads);
    for (std::size_t grain : {1u, 7u, 64u, 1000u}) {
      for (int partitioner = 0; partitioner < 3; ++partitioner) {
        Outputs got;
        const tbb::blocked_range<std::size_t> range(0, kThreadParticles, grain);
        const auto body = [&](const tbb::blocked_range<std::size_t>& r) {
          compute_block(r.begin(), r.end(), step, got.normals, got.uniforms);
        };
        arena.execute([&] {
          if (partitioner == 0) tbb::parallel_for(range, body, tbb::simple_partitioner());
          if (partitioner == 1) tbb::parallel_for(range, body, tbb::auto_partitioner());
          if (partitioner == 2) tbb::parallel_for(range, body, tbb::static_partitioner());
        });
        EXPECT_TRUE(same_bits(got.normals, want.normals))
            << threads << " threads, grain " << grain << ", partitioner " << partitioner;
        EXPECT_TRUE(same_bits(got.uniforms, want.uniforms))
            << threads << " threads, grain " << grain << ", partitioner " << partitioner;
      }
    }
  }
  Outputs got;  // the default arena
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, kThreadParticles),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      compute_block(r.begin(), r.end(), step, got.normals, got.uniforms);
                    });
  EXPECT_TRUE(same_bits(got.normals, want.normals));
  EXPECT_TRUE(same_bits(got.uniforms, want.uniforms));
}
#endif

// ----------------------------------------------------------------------------------------------
// Statistics.

struct Moments {
  double mean = 0;
  double variance = 0;
  double skewness = 0;
  double excess_kurtosis = 0;
};

Moments moments(std::span<const double> x) {
  long double sum = 0;
  for (double v : x) sum += v;
  const auto n = static_cast<long double>(x.size());
  const long double mean = sum / n;
  long double m2 = 0;
  long double m3 = 0;
  long double m4 = 0;
  for (double v : x) {
    const long double d = v - mean;
    m2 += d * d;
    m3 += d * d * d;
    m4 += d * d * d * d;
  }
  m2 /= n;
  m3 /= n;
  m4 /= n;
  return {static_cast<double>(mean), static_cast<double>(m2 * n / (n - 1)),
          static_cast<double>(m3 / std::pow(m2, 1.5L)), static_cast<double>(m4 / (m2 * m2) - 3)};
}

// Kolmogorov-Smirnov statistic sqrt(n) D_n of the sample against `cdf`.
template <class Cdf>
double ks_statistic(std::vector<double> x, Cdf cdf) {
  std::sort(x.begin(), x.end());
  const auto n = static_cast<double>(x.size());
  double d = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double f = cdf(x[i]);
    d = std::max({d, (static_cast<double>(i) + 1) / n - f, f - static_cast<double>(i) / n});
  }
  return d * std::sqrt(n);
}
// P(sqrt(n) D_n > 2.0) -> 2 sum (-1)^(k-1) exp(-2 k^2 4) = 6.7e-4 for large n; 2.2 gives 1.3e-4.
constexpr double kKsBound = 2.2;

// Upper and lower chi-square bounds for `dof` degrees of freedom at z standard normal deviates
// (Wilson-Hilferty): z = 4 is a tail probability of 3e-5 on each side.
double chi_square_quantile(double dof, double z) {
  const double a = 2.0 / (9.0 * dof);
  return dof * std::pow(1.0 - a + z * std::sqrt(a), 3.0);
}

// Pearson chi-square of bin counts against equal expectations.
double chi_square_uniform_bins(std::span<const std::size_t> counts, double draws) {
  const double expected = draws / static_cast<double>(counts.size());
  double chi2 = 0;
  for (std::size_t c : counts)
    chi2 += (static_cast<double>(c) - expected) * (static_cast<double>(c) - expected) / expected;
  return chi2;
}

void expect_chi_square_plausible(double chi2, std::size_t bins, const char* what) {
  const double dof = static_cast<double>(bins - 1);
  EXPECT_LT(chi2, chi_square_quantile(dof, 4.0)) << what;
  EXPECT_GT(chi2, chi_square_quantile(dof, -4.0)) << what;
}

double normal_cdf(double x) { return 0.5 * std::erfc(-x / std::sqrt(2.0)); }

std::vector<double> uniforms_of(const StreamKey& key, std::size_t n) {
  std::vector<double> out(n);
  RandomStream(key).fill_uniform(out);
  return out;
}
std::vector<double> normals_of(const StreamKey& key, std::size_t n) {
  std::vector<double> out(n);
  RandomStream(key).fill_normal(out);
  return out;
}

TEST(RandomStreamStatistics, UniformMomentsKsAndChiSquare) {
  // Half from one long stream, half from many particles' short batches.
  std::vector<double> u = uniforms_of({.seed = 1, .step = 0, .particle = 0}, kStatDraws / 2);
  std::vector<double> batch(kStatDraws / 2);
  uniforms_for_particles(1, 1, Purpose::kResample, 0, kStatDraws / 8, 4, batch);
  u.insert(u.end(), batch.begin(), batch.end());
  const auto n = static_cast<double>(u.size());
  for (double v : u) ASSERT_TRUE(v >= 0.0 && v < 1.0) << v;
  const Moments m = moments(u);
  EXPECT_NEAR(m.mean, 0.5, kSigmas * std::sqrt(1.0 / 12.0 / n));
  // Var(s^2) = (mu4 - sigma^4) / n with mu4 = 1/80, sigma^2 = 1/12.
  EXPECT_NEAR(m.variance, 1.0 / 12.0, kSigmas * std::sqrt((1.0 / 80.0 - 1.0 / 144.0) / n));
  EXPECT_LT(ks_statistic(u, [](double x) { return x; }), kKsBound);
  std::vector<std::size_t> bins(1000);
  for (double v : u) ++bins[static_cast<std::size_t>(v * 1000.0)];
  expect_chi_square_plausible(chi_square_uniform_bins(bins, n), bins.size(), "uniform bins");
}

TEST(RandomStreamStatistics, UniformPosIsOpenInterval) {
  RandomStream stream({.seed = 3, .step = 0, .particle = 0});
  double sum = 0;
  for (std::size_t i = 0; i < kStatDraws / 4; ++i) {
    const double v = stream.uniform_pos();
    ASSERT_TRUE(v > 0.0 && v < 1.0) << v;
    sum += v;
  }
  const auto n = static_cast<double>(kStatDraws) / 4;
  EXPECT_NEAR(sum / n, 0.5, kSigmas * std::sqrt(1.0 / 12.0 / n));
}

TEST(RandomStreamStatistics, NormalMomentsKsChiSquareAndTails) {
  std::vector<double> z = normals_of({.seed = 2, .step = 0, .particle = 0}, kStatDraws / 2);
  std::vector<double> batch(kStatDraws / 6 * 3);
  normals_for_particles(2, 1, Purpose::kMotion, 0, kStatDraws / 6, 3, batch);
  z.insert(z.end(), batch.begin(), batch.end());
  const auto n = static_cast<double>(z.size());
  const Moments m = moments(z);
  EXPECT_NEAR(m.mean, 0.0, kSigmas * std::sqrt(1.0 / n));
  EXPECT_NEAR(m.variance, 1.0, kSigmas * std::sqrt(2.0 / n));
  EXPECT_NEAR(m.skewness, 0.0, kSigmas * std::sqrt(6.0 / n));
  EXPECT_NEAR(m.excess_kurtosis, 0.0, kSigmas * std::sqrt(24.0 / n));
  EXPECT_LT(ks_statistic(z, normal_cdf), kKsBound);
  // 1000 equiprobable bins through the normal CDF.
  std::vector<std::size_t> bins(1000);
  std::size_t tails = 0;
  for (double v : z) {
    ASSERT_TRUE(std::isfinite(v));
    ++bins[std::min<std::size_t>(999, static_cast<std::size_t>(normal_cdf(v) * 1000.0))];
    if (std::abs(v) > 3.5) ++tails;
  }
  expect_chi_square_plausible(chi_square_uniform_bins(bins, n), bins.size(), "normal bins");
  // P(|Z| > 3.5) = 4.65e-4: the tails are populated as they should be (Poisson, 5 sigma).
  const double expected_tails = n * std::erfc(3.5 / std::sqrt(2.0));
  EXPECT_NEAR(static_cast<double>(tails), expected_tails, kSigmas * std::sqrt(expected_tails));
}

// Pearson correlation of paired samples; under independence sqrt(n) r is about N(0, 1).
double correlation(std::span<const double> a, std::span<const double> b) {
  const Moments ma = moments(a);
  const Moments mb = moments(b);
  long double s = 0;
  for (std::size_t i = 0; i < a.size(); ++i) s += (a[i] - ma.mean) * (b[i] - mb.mean);
  return static_cast<double>(s / static_cast<long double>(a.size() - 1) /
                             std::sqrt(static_cast<long double>(ma.variance) * mb.variance));
}

constexpr std::size_t kGrid = 32;

// Chi-square of the pairs (a_i, b_i) on a kGrid x kGrid grid: catches dependence a correlation
// misses.
double pair_chi_square(std::span<const double> a, std::span<const double> b) {
  std::vector<std::size_t> grid(kGrid * kGrid);
  for (std::size_t i = 0; i < a.size(); ++i) {
    ++grid[static_cast<std::size_t>(a[i] * kGrid) * kGrid + static_cast<std::size_t>(b[i] * kGrid)];
  }
  return chi_square_uniform_bins(grid, static_cast<double>(a.size()));
}

void expect_independent_uniforms(std::span<const double> a, std::span<const double> b,
                                 const char* what) {
  const double n = static_cast<double>(a.size());
  EXPECT_LT(std::abs(correlation(a, b)), kSigmas / std::sqrt(n)) << what;
  expect_chi_square_plausible(pair_chi_square(a, b), kGrid * kGrid, what);
}

void expect_uncorrelated_normals(std::span<const double> a, std::span<const double> b,
                                 const char* what) {
  const double n = static_cast<double>(a.size());
  EXPECT_LT(std::abs(correlation(a, b)), kSigmas / std::sqrt(n)) << what;
  // Also the squares (dependence through the Box-Muller radius): corr(a^2, b^2) ~ N(0, 1/n).
  std::vector<double> a2(a.begin(), a.end());
  std::vector<double> b2(b.begin(), b.end());
  for (double& v : a2) v *= v;
  for (double& v : b2) v *= v;
  EXPECT_LT(std::abs(correlation(a2, b2)), kSigmas / std::sqrt(n)) << what << " (squares)";
}

TEST(RandomStreamStatistics, NeighbouringKeysAreIndependent) {
  const std::size_t n = kStatDraws / 4;
  const std::size_t per = 4;
  // Particle k vs k + 1: draw j of particle k paired with draw j of particle k + 1.
  {
    std::vector<double> u((n / per + 1) * per);
    uniforms_for_particles(9, 5, Purpose::kProposal, 0, n / per + 1, per, u);
    expect_independent_uniforms(std::span(u).first(n), std::span(u).subspan(per, n),
                                "particle k vs k + 1 (uniforms)");
    std::vector<double> z((n / per + 1) * per);
    normals_for_particles(9, 5, Purpose::kMotion, 0, n / per + 1, per, z);
    expect_uncorrelated_normals(std::span(z).first(n), std::span(z).subspan(per, n),
                                "particle k vs k + 1 (normals)");
  }
  // Step s vs s + 1, purpose a vs b, seed vs seed + 1, over the same particles.
  const auto batch_u = [&](std::uint64_t seed, std::uint64_t step, Purpose purpose) {
    std::vector<double> u(n);
    uniforms_for_particles(seed, step, purpose, 0, n / per, per, u);
    return u;
  };
  const auto batch_z = [&](std::uint64_t seed, std::uint64_t step, Purpose purpose) {
    std::vector<double> z(n);
    normals_for_particles(seed, step, purpose, 0, n / per, per, z);
    return z;
  };
  expect_independent_uniforms(batch_u(9, 5, Purpose::kMotion), batch_u(9, 6, Purpose::kMotion),
                              "step s vs s + 1");
  expect_independent_uniforms(batch_u(9, 5, Purpose::kMotion),
                              batch_u(9, 5 + (std::uint64_t{1} << 32), Purpose::kMotion),
                              "step s vs s + 2^32");
  expect_independent_uniforms(batch_u(9, 5, Purpose::kMotion), batch_u(9, 5, Purpose::kProposal),
                              "purpose motion vs proposal");
  expect_independent_uniforms(batch_u(9, 5, Purpose::kUser),
                              batch_u(9, 5, static_cast<Purpose>(65)), "purpose user vs user + 1");
  expect_independent_uniforms(batch_u(9, 5, Purpose::kMotion), batch_u(10, 5, Purpose::kMotion),
                              "seed vs seed + 1");
  expect_uncorrelated_normals(batch_z(9, 5, Purpose::kMotion), batch_z(9, 6, Purpose::kMotion),
                              "step s vs s + 1 (normals)");
  expect_uncorrelated_normals(batch_z(9, 5, Purpose::kMotion), batch_z(9, 5, Purpose::kProposal),
                              "purpose motion vs proposal (normals)");
  expect_uncorrelated_normals(batch_z(0, 5, Purpose::kMotion), batch_z(1, 5, Purpose::kMotion),
                              "seed 0 vs 1 (normals)");
}

TEST(RandomStreamStatistics, SuccessiveDrawsInAStreamAreIndependent) {
  const std::size_t n = kStatDraws / 4;
  const std::vector<double> u = uniforms_of({.seed = 4, .step = 0, .particle = 0}, n + 1);
  expect_independent_uniforms(std::span(u).first(n), std::span(u).subspan(1, n), "lag 1");
  const std::vector<double> z = normals_of({.seed = 4, .step = 0, .particle = 1}, 2 * n + 2);
  std::vector<double> even(n);
  std::vector<double> odd(n);
  for (std::size_t i = 0; i < n; ++i) {  // the two halves of each pair, and pair i vs i + 1
    even[i] = z[2 * i];
    odd[i] = z[2 * i + 1];
  }
  expect_uncorrelated_normals(even, odd, "cos vs sin half of a pair");
  expect_uncorrelated_normals(std::span(z).first(n), std::span(z).subspan(1, n), "lag 1 normals");
  expect_uncorrelated_normals(std::span(z).first(n), std::span(z).subspan(2, n), "lag 2 normals");
}

}  // namespace
}  // namespace fastslam::parallel
