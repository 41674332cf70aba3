// The batch kernels of parallel/random_stream.h for one instruction set (random_kernels.h):
// Philox blocks side by side (explicit AVX-512 / AVX2 rounds where the flags of this copy have
// them, loops the compiler vectorises otherwise) and their uniforms or Box-Muller pairs.
// FASTSLAM_RANDOM_KERNELS names the copy (parallel/CMakeLists.txt compiles this file once per
// name); everything but kernels(), its table, has internal linkage, so copies for different
// instruction sets never share a function.
// Thread safety: pure functions on disjoint outputs. Costs: O(blocks); no allocation.
#include "parallel/internal/random_kernels.h"

#include <algorithm>
#include <cassert>
#include <cstddef>
#include <cstdint>
#include <span>

#include "parallel/internal/philox.h"
#include "parallel/random_stream.h"

#if !defined(FASTSLAM_RANDOM_KERNELS)
#error "FASTSLAM_RANDOM_KERNELS must name this copy of the kernels (parallel/CMakeLists.txt)"
#endif
#define FASTSLAM_KERNELS_CONCAT_(a, b) a##b
#define FASTSLAM_KERNELS_CONCAT(a, b) FASTSLAM_KERNELS_CONCAT_(a, b)
#define FASTSLAM_KERNELS_STRING_(a) #a
#define FASTSLAM_KERNELS_STRING(a) FASTSLAM_KERNELS_STRING_(a)

#define FASTSLAM_KERNELS_NAMESPACE FASTSLAM_KERNELS_CONCAT(kernels_, FASTSLAM_RANDOM_KERNELS)

namespace fastslam::parallel::internal::FASTSLAM_KERNELS_NAMESPACE {
namespace {

// Philox blocks computed side by side in the batch paths: 16 lanes of 64 bits = two AVX-512
// (four AVX2) registers per counter word; the last few blocks of a batch go 4 at a time.
constexpr std::size_t kLanes = 16;
constexpr std::size_t kTailLanes = 4;

// The two 64-bit draws of lane l's block.
template <std::size_t L>
[[gnu::always_inline]] inline std::uint64_t first_u64(const PhiloxLanes<L>& lanes,
                                                      std::size_t l) noexcept {
  return lanes.x0[l] | lanes.x1[l] << 32;
}
template <std::size_t L>
[[gnu::always_inline]] inline std::uint64_t second_u64(const PhiloxLanes<L>& lanes,
                                                       std::size_t l) noexcept {
  return lanes.x2[l] | lanes.x3[l] << 32;
}

// Each lane's block to two normals (cos, sin halves of its Box-Muller pair).
struct LanesToNormals {
  template <std::size_t L>
  void operator()(const PhiloxLanes<L>& lanes, double* z0, double* z1) const noexcept {
    for (std::size_t l = 0; l < L; ++l) {
      box_muller(first_u64(lanes, l), second_u64(lanes, l), z0[l], z1[l]);
    }
  }
};

// Each lane's block to two uniforms.
struct LanesToUniforms {
  template <std::size_t L>
  void operator()(const PhiloxLanes<L>& lanes, double* u0, double* u1) const noexcept {
    for (std::size_t l = 0; l < L; ++l) {
      u0[l] = uniform_from_bits(first_u64(lanes, l));
      u1[l] = uniform_from_bits(second_u64(lanes, l));
    }
  }
};

// Blocks first_block .. first_block + blocks - 1 of one particle's stream, two values per block,
// written to out[0 .. 2 * blocks): kLanes blocks at a time, the rest kTailLanes at a time.
template <std::size_t L, class Convert>
[[gnu::noinline]] void stream_chunk(const KeyWords& kw, std::uint32_t particle,
                                    std::uint64_t first_block, std::size_t n, double* out,
                                    Convert convert) noexcept {
  PhiloxLanes<L> lanes{};
  for (std::size_t l = 0; l < L; ++l) {
    lanes.x0[l] = (first_block + l) & 0xFFFFFFFFu;  // lanes past n are computed, not stored
    lanes.x1[l] = particle;
  }
  philox4x32_10_lanes(kw.key, kw.step_low, kw.step_high_purpose, lanes);
  alignas(64) double v0[L];
  alignas(64) double v1[L];
  convert(lanes, v0, v1);
  for (std::size_t l = 0; l < n; ++l) {
    out[2 * l] = v0[l];
    out[2 * l + 1] = v1[l];
  }
}

template <class Convert>
void stream_blocks(const KeyWords& kw, std::uint32_t particle, std::uint64_t first_block,
                   std::uint64_t blocks, double* out, Convert convert) noexcept {
  assert(first_block + blocks <= (std::uint64_t{1} << 32) && "more than 2^32 blocks per stream");
  std::uint64_t done = 0;
  for (; blocks - done >= kLanes; done += kLanes) {
    stream_chunk<kLanes>(kw, particle, first_block + done, kLanes, out + 2 * done, convert);
  }
  for (; done < blocks; done += kTailLanes) {
    const auto n = static_cast<std::size_t>(std::min<std::uint64_t>(kTailLanes, blocks - done));
    stream_chunk<kTailLanes>(kw, particle, first_block + done, n, out + 2 * done, convert);
  }
}

// Where a batch is: its next item is block `block` of particle first_particle + `particle`, whose
// two values go to dst[0], dst[1].
struct BatchCursor {
  std::uint64_t particle = 0;
  std::uint64_t block = 0;
  double* dst = nullptr;
};

// The next n <= L items of a batch. Items (particle k, block b) are enumerated particle-major;
// item (k, b) fills out[k * per_particle + 2b] and out[k * per_particle + 2b + 1]. For an odd
// per_particle the second value of a particle's last block lands on the next particle's first
// entry, which that particle's first item (the next one in order) overwrites; only the very last
// item of the batch (`ends_batch`) must skip it, as it would fall past the end of out.
template <std::size_t L, class Convert>
[[gnu::noinline]] void particle_chunk(const KeyWords& kw, std::uint32_t first_particle,
                                      std::uint64_t blocks, bool odd, std::size_t n,
                                      bool ends_batch, BatchCursor& at, Convert convert) noexcept {
  PhiloxLanes<L> lanes{};
  std::uint64_t k = at.particle;
  std::uint64_t b = at.block;
  for (std::size_t l = 0; l < L; ++l) {  // lanes past n are computed, not stored
    lanes.x0[l] = b & 0xFFFFFFFFu;
    lanes.x1[l] = (first_particle + k) & 0xFFFFFFFFu;
    if (++b == blocks) {
      b = 0;
      ++k;
    }
  }
  philox4x32_10_lanes(kw.key, kw.step_low, kw.step_high_purpose, lanes);
  alignas(64) double v0[L];
  alignas(64) double v1[L];
  convert(lanes, v0, v1);
  const std::size_t paired = ends_batch && odd ? n - 1 : n;
  double* dst = at.dst;
  k = at.particle;
  b = at.block;
  for (std::size_t l = 0; l < n; ++l) {
    dst[0] = v0[l];
    if (l < paired) dst[1] = v1[l];
    dst += 2;
    if (++b == blocks) {
      b = 0;
      ++k;
      if (odd) --dst;  // the particle had per_particle = 2 blocks - 1 entries
    }
  }
  at = {k, b, dst};
}

// out[k * per_particle + j] = value j of particle first_particle + k. Items are processed
// kLanes at a time regardless of particle boundaries, so short streams (per_particle = 3: two
// blocks) still fill whole vectors; the last few go kTailLanes at a time.
template <class Convert>
void particle_blocks(const KeyWords& kw, std::uint32_t first_particle, std::size_t count,
                     std::size_t per_particle, double* out, Convert convert) noexcept {
  if (count == 0 || per_particle == 0) return;
  assert(std::uint64_t{first_particle} + count <= (std::uint64_t{1} << 32) &&
         "first_particle + count must not exceed 2^32");
  const std::uint64_t blocks = (std::uint64_t{per_particle} + 1) / 2;
  assert(blocks <= (std::uint64_t{1} << 32) && "more than 2^32 blocks per stream");
  const bool odd = per_particle % 2 != 0;
  const std::uint64_t items = std::uint64_t{count} * blocks;
  BatchCursor at{0, 0, out};
  std::uint64_t done = 0;
  for (; items - done >= kLanes; done += kLanes) {
    particle_chunk<kLanes>(kw, first_particle, blocks, odd, kLanes, done + kLanes == items, at,
                           convert);
  }
  for (; done < items; done += kTailLanes) {
    const auto n = static_cast<std::size_t>(std::min<std::uint64_t>(kTailLanes, items - done));
    particle_chunk<kTailLanes>(kw, first_particle, blocks, odd, n, done + n == items, at, convert);
  }
}

#if defined(__AVX512F__)
// Chunks of pair_run on AVX-512 (see there).
constexpr std::size_t kPairChunk = 32;

// The first block of the streams of particles first + l, l < L (counter {0, first + l, c2,
// c3}), as the two 64-bit draws a[l] = word 0 | word 1 << 32, b[l] = word 2 | word 3 << 32.
// Only counter word 1 varies across lanes, so the first three rounds are partly the same in every
// lane: word 0 starts at 0 (round 0's first product is 0), and of the words each round
// multiplies, one depends on the lane in round 1 and in round 2 and none in round 0. Those parts
// are computed once, in scalar code, the same products as philox4x32_10 (the test compares).
template <std::size_t L>
[[gnu::always_inline]] inline void pair_words_avx512(const PhiloxRoundKeys& keys, std::uint64_t c2,
                                                     std::uint64_t c3, std::uint32_t first,
                                                     std::uint64_t* a, std::uint64_t* b) noexcept {
  static_assert(L % 8 == 0);
  constexpr std::size_t kV = L % 32 == 0 ? 4 : L % 16 == 0 ? 2 : 1;
  constexpr std::uint64_t kLow = 0xFFFFFFFFu;
  const auto splat = [](std::uint64_t v) { return _mm512_set1_epi64(static_cast<long long>(v)); };
  // Round 0 on {0, w1, c2, c3}: {hi(M1 c2) ^ w1 ^ k0, lo(M1 c2), c3 ^ k1, 0}.
  const std::uint64_t r0p1 = kPhiloxM1 * c2;
  const std::uint64_t r0x0 = (r0p1 >> 32) ^ keys.k0[0];  // ^ w1 per lane
  const std::uint64_t r0x1 = r0p1 & kLow;
  const std::uint64_t r0x2 = c3 ^ keys.k1[0];
  // Round 1 on {x0 (lane), r0x1, r0x2, 0}: {hi(M1 r0x2) ^ r0x1 ^ k0, lo(M1 r0x2),
  // hi(M0 x0) ^ k1, lo(M0 x0)}.
  const std::uint64_t r1p1 = kPhiloxM1 * r0x2;
  const std::uint64_t r1x0 = (r1p1 >> 32) ^ r0x1 ^ keys.k0[1];
  const std::uint64_t r1x1 = r1p1 & kLow;
  // Round 2 on {r1x0, r1x1, x2 (lane), x3 (lane)}: {hi(M1 x2) ^ r1x1 ^ k0, lo(M1 x2),
  // hi(M0 r1x0) ^ x3 ^ k1, lo(M0 r1x0)}.
  const std::uint64_t r2p0 = kPhiloxM0 * r1x0;
  const __m512i m0 = splat(kPhiloxM0);
  const __m512i m1 = splat(kPhiloxM1);
  const __m512i k1_1 = splat(keys.k1[1]);
  const __m512i r0x0_v = splat(r0x0);
  const __m512i r1x1_k = splat(r1x1 ^ keys.k0[2]);
  const __m512i r2p0_k = splat((r2p0 >> 32) ^ keys.k1[2]);
  const __m512i r2x3 = splat(r2p0 & kLow);
  const __m512i low = splat(kLow);
  const __m512i iota = _mm512_set_epi64(7, 6, 5, 4, 3, 2, 1, 0);
  for (std::size_t l = 0; l < L; l += 8 * kV) {
    __m512i x0[kV];
    __m512i x1[kV];
    __m512i x2[kV];
    __m512i x3[kV];
    for (std::size_t v = 0; v < kV; ++v) {
      // Counter word 1 wraps modulo 2^32 like the scalar path's: high halves are ignored.
      const __m512i w1 = _mm512_add_epi64(splat(std::uint64_t{first} + l + 8 * v), iota);
      const __m512i p0 = mul_epu32_512(m0, _mm512_xor_si512(w1, r0x0_v));  // round 1
      const __m512i y2 = _mm512_xor_si512(srli32_512(p0), k1_1);
      const __m512i p1 = mul_epu32_512(m1, y2);  // round 2
      x0[v] = _mm512_xor_si512(srli32_512(p1), r1x1_k);
      x1[v] = p1;
      x2[v] = _mm512_xor_si512(p0, r2p0_k);
      x3[v] = r2x3;
    }
    philox_rounds_avx512<kV, 3>(keys, x0, x1, x2, x3);
    for (std::size_t v = 0; v < kV; ++v) {
      _mm512_store_si512(a + l + 8 * v,
                         _mm512_ternarylogic_epi64(x0[v], low, slli32_512(x1[v]), 0xEA));
      _mm512_store_si512(b + l + 8 * v,
                         _mm512_ternarylogic_epi64(x2[v], low, slli32_512(x3[v]), 0xEA));
    }
  }
}
#endif

// For each step j: the first Box-Muller pair (block 0) of the streams of particles
// first_particle + k, k < n, to z0[j * stride + k] and z1[j * stride + k]. With AVX-512 or
// AVX2, chunks of lanes by the explicit SIMD rounds and then the transform; otherwise (and for a
// remainder below 8) Philox and the transform fused in one loop over particles. The round keys
// are set up once for all steps.
[[gnu::noinline]] void pair_run(std::uint64_t seed, std::span<const std::uint64_t> steps,
                                Purpose purpose, std::uint32_t first_particle, std::size_t n,
                                double* z0, double* z1, std::size_t stride) noexcept {
  const PhiloxRoundKeys keys = philox_round_keys(key_words(seed, 0, purpose).key);
  for (std::size_t j = 0; j < steps.size(); ++j) {
    const KeyWords kw = key_words(seed, steps[j], purpose);
    const std::uint64_t c2 = kw.step_low;
    const std::uint64_t c3 = kw.step_high_purpose;
    double* out0 = z0 + j * stride;
    double* out1 = z1 + j * stride;
    std::size_t k = 0;
#if defined(__AVX512F__)
    // Whole chunks in two passes: the blocks of the chunk by the explicit rounds, four vectors
    // side by side, to the draws a, b; then the transform over the chunk, vectorised by the
    // compiler. Fused in one loop (one vector per iteration), both passes form one long
    // dependency chain per vector (ten multiply rounds, a division, a square root) that the
    // out-of-order window cannot overlap with the next; separate, the iterations of each pass
    // are short and independent. Then chunks of 8; a remainder below 8 is scalar.
    auto chunk = [&]<std::size_t kChunk>(std::size_t at) __attribute__((always_inline)) {
      alignas(64) std::uint64_t a[kChunk];
      alignas(64) std::uint64_t b[kChunk];
      pair_words_avx512<kChunk>(keys, c2, c3, first_particle + static_cast<std::uint32_t>(at), a,
                                b);
      for (std::size_t l = 0; l < kChunk; ++l) box_muller(a[l], b[l], out0[at + l], out1[at + l]);
    };
    for (; k + kPairChunk <= n; k += kPairChunk) chunk.template operator()<kPairChunk>(k);
    for (; k + 8 <= n; k += 8) chunk.template operator()<8>(k);
#else
    if constexpr (kPhiloxSimdLanes > 0) {
      // Whole chunks: the words by the explicit SIMD rounds, then the transform over the chunk
      // (vectorised by the compiler); the same values as the fused loop below. Chunks of 16,
      // then of 8 (a filter block of 104 lanes: six and one), so that only a remainder below 8
      // takes the scalar loop, at about four times the cost per lane.
      auto chunk = [&]<std::size_t kChunk>(std::size_t at) __attribute__((always_inline)) {
        alignas(64) std::uint64_t w0[kChunk];
        alignas(64) std::uint64_t w1[kChunk];
        alignas(64) std::uint64_t w2[kChunk];
        alignas(64) std::uint64_t w3[kChunk];
        for (std::size_t l = 0; l < kChunk; ++l) {
          w0[l] = 0;
          w1[l] = (first_particle + at + l) & 0xFFFFFFFFu;
          w2[l] = c2;
          w3[l] = c3;
        }
        philox4x32_10_simd<kChunk>(keys, w0, w1, w2, w3);
        for (std::size_t l = 0; l < kChunk; ++l) {
          box_muller(w0[l] | w1[l] << 32, w2[l] | w3[l] << 32, out0[at + l], out1[at + l]);
        }
      };
      for (; k + 16 <= n; k += 16) chunk.template operator()<16>(k);
      if constexpr (8 % kPhiloxSimdStep == 0) {
        for (; k + 8 <= n; k += 8) chunk.template operator()<8>(k);
      }
    }
#endif
    for (; k < n; ++k) {
      std::uint64_t x0 = 0;
      std::uint64_t x1 = (first_particle + k) & 0xFFFFFFFFu;
      std::uint64_t x2 = c2;
      std::uint64_t x3 = c3;
      philox4x32_10_words(keys, x0, x1, x2, x3);
      box_muller(x0 | x1 << 32, x2 | x3 << 32, out0[k], out1[k]);
    }
  }
}

}  // namespace

const RandomKernels& kernels() noexcept {
  static constexpr RandomKernels kKernels{
      .name = FASTSLAM_KERNELS_STRING(FASTSLAM_RANDOM_KERNELS),
      .stream_normals =
          [](const KeyWords& kw, std::uint32_t particle, std::uint64_t first_block,
             std::uint64_t blocks, double* out) noexcept {
            stream_blocks(kw, particle, first_block, blocks, out, LanesToNormals{});
          },
      .stream_uniforms =
          [](const KeyWords& kw, std::uint32_t particle, std::uint64_t first_block,
             std::uint64_t blocks, double* out) noexcept {
            stream_blocks(kw, particle, first_block, blocks, out, LanesToUniforms{});
          },
      .particle_normals =
          [](const KeyWords& kw, std::uint32_t first_particle, std::size_t count,
             std::size_t per_particle, double* out) noexcept {
            particle_blocks(kw, first_particle, count, per_particle, out, LanesToNormals{});
          },
      .particle_uniforms =
          [](const KeyWords& kw, std::uint32_t first_particle, std::size_t count,
             std::size_t per_particle, double* out) noexcept {
            particle_blocks(kw, first_particle, count, per_particle, out, LanesToUniforms{});
          },
      .normal_pairs = pair_run,
  };
  return kKernels;
}

}  // namespace fastslam::parallel::internal::FASTSLAM_KERNELS_NAMESPACE
