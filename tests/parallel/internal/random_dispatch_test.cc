// Tests of parallel/internal/random_dispatch.h and of the copies of the batch kernels
// (parallel/internal/random_kernels.h): the choice of a copy (a request honoured, refused with a
// warning, the CPU's best by default), the process's choice following FASTSLAM_ISA
// (tests/parallel/CMakeLists.txt runs it under each copy's name in a portable build), and every
// copy this CPU runs giving the bits of the first (baseline) copy for every entry point: every
// size around the SIMD widths, odd and even per_particle, first particles and blocks next to
// 2^32, extreme keys. In a build with one copy the last test has nothing to compare and skips.
#include "parallel/internal/random_dispatch.h"

#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <gtest/gtest.h>

#include "parallel/internal/random_kernels.h"
#include "parallel/random_stream.h"

namespace fastslam::parallel::internal {
namespace {

constexpr RandomKernels kFakeBaseline{.name = "baseline"};
constexpr RandomKernels kFakeAvx2{.name = "avx2"};
constexpr RandomKernels kFakeAvx512{.name = "avx512"};

// A CPU with AVX2 but not AVX-512.
constexpr RandomKernelVariant kFakeVariants[] = {
    {&kFakeBaseline, true}, {&kFakeAvx2, true}, {&kFakeAvx512, false}};

TEST(RandomDispatch, WithoutARequestTheMostCapableSupportedCopy) {
  for (const char* request : {static_cast<const char*>(nullptr), "", "auto"}) {
    const RandomKernelChoice choice = choose_random_kernels(kFakeVariants, request);
    EXPECT_EQ(choice.kernels, &kFakeAvx2);
    EXPECT_EQ(choice.warning, "");
  }
  const RandomKernelVariant only[] = {{&kFakeBaseline, true}};
  EXPECT_EQ(choose_random_kernels(only, nullptr).kernels, &kFakeBaseline);
}

TEST(RandomDispatch, ARequestForASupportedCopyIsHonoured) {
  for (const RandomKernels* k : {&kFakeBaseline, &kFakeAvx2}) {
    const std::string name(k->name);
    const RandomKernelChoice choice = choose_random_kernels(kFakeVariants, name.c_str());
    EXPECT_EQ(choice.kernels, k);
    EXPECT_EQ(choice.warning, "");
  }
}

TEST(RandomDispatch, ARequestThatCannotBeHonouredFallsBackWithAWarning) {
  const RandomKernelChoice unsupported = choose_random_kernels(kFakeVariants, "avx512");
  EXPECT_EQ(unsupported.kernels, &kFakeAvx2);
  EXPECT_EQ(unsupported.warning,
            "fastslam: FASTSLAM_ISA=avx512: this CPU cannot run those kernels; using avx2");
  const RandomKernelChoice unknown = choose_random_kernels(kFakeVariants, "AVX2");
  EXPECT_EQ(unknown.kernels, &kFakeAvx2);
  EXPECT_EQ(unknown.warning,
            "fastslam: FASTSLAM_ISA=AVX2 is not one of this build's random-stream kernels "
            "(baseline, avx2, avx512; or auto); using avx2");
}

TEST(RandomDispatch, TheBuildListsItsCopiesBaselineFirst) {
  const std::span<const RandomKernelVariant> variants = random_kernel_variants();
  ASSERT_FALSE(variants.empty());
  EXPECT_TRUE(variants[0].supported);
  std::vector<std::string_view> names;
  for (const RandomKernelVariant& v : variants) {
    ASSERT_NE(v.kernels, nullptr);
    names.push_back(v.kernels->name);
    std::cout << v.kernels->name << (v.supported ? " (this CPU runs it)\n" : " (not here)\n");
  }
  if (names.size() > 1) {
    EXPECT_EQ(names, (std::vector<std::string_view>{"baseline", "avx2", "avx512"}));
  } else {
    EXPECT_TRUE(names[0] == "native" || names[0] == "baseline") << names[0];
  }
}

TEST(RandomDispatch, TheProcessFollowsFastslamIsa) {
  const char* requested = std::getenv("FASTSLAM_ISA");
  const RandomKernelChoice expected = choose_random_kernels(random_kernel_variants(), requested);
  EXPECT_EQ(random_stream_isa(), expected.kernels->name);
  EXPECT_EQ(&random_kernels(), expected.kernels);
  std::cout << "FASTSLAM_ISA=" << (requested == nullptr ? "(unset)" : requested)
            << ", kernels in use: " << random_stream_isa() << "\n";
  if (requested != nullptr && expected.warning.empty() && std::string_view(requested) != "auto" &&
      std::string_view(requested) != "") {
    EXPECT_EQ(random_stream_isa(), requested);
  }
}

// ----------------------------------------------------------------------------------------------
// Every copy against the first.

bool same_bits(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

constexpr std::uint64_t kSeeds[] = {0, ~std::uint64_t{0}, 0x0123456789abcdefu};
constexpr double kCanary = -7.0;  // past the outputs: must stay untouched

void expect_stream_blocks_match(const RandomKernels& want, const RandomKernels& got) {
  for (const std::uint64_t seed : kSeeds) {
    const KeyWords kw = key_words(seed, 0xFFFFFF12345678u, Purpose::kSimulator);
    for (const std::uint64_t first_block :
         {std::uint64_t{0}, std::uint64_t{3}, std::uint64_t{0xFFFFFFFFu - 80}}) {
      for (std::uint64_t blocks = 0; blocks <= 72; ++blocks) {
        for (const bool normals : {true, false}) {
          std::vector<double> a(2 * blocks + 2, kCanary);
          std::vector<double> b(2 * blocks + 2, kCanary);
          (normals ? want.stream_normals : want.stream_uniforms)(kw, 0xFFFFFFFFu, first_block,
                                                                 blocks, a.data());
          (normals ? got.stream_normals : got.stream_uniforms)(kw, 0xFFFFFFFFu, first_block, blocks,
                                                               b.data());
          ASSERT_TRUE(same_bits(a, b))
              << got.name << (normals ? " normals" : " uniforms") << " seed " << seed
              << " first block " << first_block << " blocks " << blocks;
        }
      }
    }
  }
}

void expect_particle_blocks_match(const RandomKernels& want, const RandomKernels& got) {
  for (const std::uint64_t seed : kSeeds) {
    const KeyWords kw = key_words(seed, 41, Purpose::kProposal);
    for (const std::uint32_t first : {0u, 5u, 0xFFFFFFFFu - 60u}) {
      for (std::size_t count = 0; count <= 40; ++count) {
        for (std::size_t per_particle = 1; per_particle <= 7; ++per_particle) {
          for (const bool normals : {true, false}) {
            std::vector<double> a(count * per_particle + 1, kCanary);
            std::vector<double> b(count * per_particle + 1, kCanary);
            (normals ? want.particle_normals : want.particle_uniforms)(kw, first, count,
                                                                       per_particle, a.data());
            (normals ? got.particle_normals : got.particle_uniforms)(kw, first, count, per_particle,
                                                                     b.data());
            ASSERT_TRUE(same_bits(a, b))
                << got.name << (normals ? " normals" : " uniforms") << " seed " << seed << " first "
                << first << " count " << count << " per_particle " << per_particle;
          }
        }
      }
    }
  }
}

void expect_normal_pairs_match(const RandomKernels& want, const RandomKernels& got) {
  const std::uint64_t step_values[] = {0, 0xFFFFFFFFu, (std::uint64_t{0xFFFFFF} << 32) | 7,
                                       123456789};
  const std::span<const std::uint64_t> steps(step_values);
  for (const std::uint64_t seed : kSeeds) {
    for (const std::uint32_t first : {0u, 5u, 0xFFFFFFFFu - 90u}) {
      for (std::size_t count = 1; count <= 80; ++count) {
        const std::size_t stride = count + 3;
        std::vector<double> a0(steps.size() * stride, kCanary);
        std::vector<double> a1(a0);
        std::vector<double> b0(a0);
        std::vector<double> b1(a0);
        want.normal_pairs(seed, steps, Purpose::kMotion, first, count, a0.data(), a1.data(),
                          stride);
        got.normal_pairs(seed, steps, Purpose::kMotion, first, count, b0.data(), b1.data(), stride);
        ASSERT_TRUE(same_bits(a0, b0) && same_bits(a1, b1))
            << got.name << " seed " << seed << " first " << first << " count " << count;
      }
    }
  }
}

TEST(RandomDispatch, EveryCopyThisCpuRunsGivesTheBitsOfTheFirst) {
  const std::span<const RandomKernelVariant> variants = random_kernel_variants();
  if (variants.size() < 2) GTEST_SKIP() << "one copy in this build: " << variants[0].kernels->name;
  const RandomKernels& first = *variants[0].kernels;
  std::size_t compared = 0;
  for (const RandomKernelVariant& v : variants.subspan(1)) {
    if (!v.supported) {
      std::cout << v.kernels->name << ": this CPU cannot run it, not compared\n";
      continue;
    }
    SCOPED_TRACE(std::string(v.kernels->name));
    expect_stream_blocks_match(first, *v.kernels);
    expect_particle_blocks_match(first, *v.kernels);
    expect_normal_pairs_match(first, *v.kernels);
    ++compared;
  }
  std::cout << compared << " copies compared with " << first.name << "\n";
}

}  // namespace
}  // namespace fastslam::parallel::internal
