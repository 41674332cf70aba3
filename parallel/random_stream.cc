#include "parallel/random_stream.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cassert>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>

#include "parallel/internal/philox.h"
#include "parallel/internal/vmath.h"

namespace fastslam::parallel {
namespace {

using internal::philox4x32_10;
using internal::philox4x32_10_lanes;
using internal::PhiloxKey;
using internal::PhiloxLanes;

// Compile-time self-check against Random123's known-answer vectors (kat_vectors there).
static_assert(philox4x32_10({0, 0, 0, 0}, {0, 0}) ==
              internal::PhiloxCounter{0x6627e8d5u, 0xe169c58du, 0xbc57ac4cu, 0x9b00dbd8u});
static_assert(philox4x32_10({0xffffffffu, 0xffffffffu, 0xffffffffu, 0xffffffffu},
                            {0xffffffffu, 0xffffffffu}) ==
              internal::PhiloxCounter{0x408f276du, 0x41c83b0eu, 0xa20bc7c6u, 0x6d5451fdu});
static_assert(philox4x32_10({0x243f6a88u, 0x85a308d3u, 0x13198a2eu, 0x03707344u},
                            {0xa4093822u, 0x299f31d0u}) ==
              internal::PhiloxCounter{0xd16cfe09u, 0x94fdccebu, 0x5001e420u, 0x24126ea1u});

// Philox blocks computed side by side in the batch paths: 16 lanes of 64 bits = two AVX-512
// (four AVX2) registers per counter word; the last few blocks of a batch go 4 at a time.
constexpr std::size_t kLanes = 16;
constexpr std::size_t kTailLanes = 4;

// ---------------------------------------------------------------------------------------------
// Floating point: log and sin/cos of parallel/internal/vmath.h, written so that the scalar and
// the vectorised paths give the same bits (see there), and std::sqrt, correctly rounded, which
// this file's -fno-math-errno (parallel/CMakeLists.txt) turns into one instruction in both
// paths (with errno semantics it would not vectorise; the argument is never negative anyway,
// so errno is never set). random_stream_test checks the composite Box-Muller pair (within 8
// ulp of max(r, 1)).

using internal::log_positive;
using internal::sincos_turns;

// An integer v <= 2^53 as a double, exactly. AVX-512DQ converts int64 directly (vcvtqq2pd);
// AVX2 has no such instruction, and with the conversion GCC does not vectorise the transform's
// loops there, so other targets place the two 32-bit halves in the mantissas of 2^84 and 2^52
// (bit operations and two exact floating-point steps). Both are exact: the same bits.
[[gnu::always_inline]] inline double exact_double(std::uint64_t v) noexcept {
#if defined(__AVX512DQ__)
  return static_cast<double>(static_cast<std::int64_t>(v));
#else
  const double high = std::bit_cast<double>(0x4530000000000000u | (v >> 32)) - 0x1p84;
  const double low = std::bit_cast<double>(0x4330000000000000u | (v & 0xFFFFFFFFu)) - 0x1p52;
  return high + low;  // exact: v is representable
#endif
}

// Box-Muller on two 64-bit draws (see the header).
[[gnu::always_inline]] inline void box_muller(std::uint64_t a, std::uint64_t b, double& z0,
                                              double& z1) noexcept {
  // u = ((a >> 11) + 1) 2^-53 in (0, 1], a normal number: the scaling is exact, so it is done
  // on the exponent bits (an integer subtraction, off the multiply pipes), the same bits.
  const double u = std::bit_cast<double>(std::bit_cast<std::uint64_t>(exact_double((a >> 11) + 1)) -
                                         (std::uint64_t{53} << 52));
  const double radius = std::sqrt(-2.0 * log_positive(u));
  double c = 0.0;
  double s = 0.0;
  sincos_turns(exact_double(b >> 11), c, s);
  z0 = radius * c;
  z1 = radius * s;
}

// ---------------------------------------------------------------------------------------------
// Keys and lanes.

struct KeyWords {
  PhiloxKey key;
  std::uint32_t step_low;
  std::uint32_t step_high_purpose;
};

KeyWords key_words(std::uint64_t seed, std::uint64_t step, Purpose purpose) noexcept {
  assert(step < (std::uint64_t{1} << 56) && "step must be below 2^56");
  assert(static_cast<std::uint32_t>(purpose) < 256 && "purpose must be below 256");
  return {{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32)},
          static_cast<std::uint32_t>(step),
          (static_cast<std::uint32_t>(purpose) & 0xFFu) << 24 |
              (static_cast<std::uint32_t>(step >> 32) & 0xFFFFFFu)};
}

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
[[gnu::always_inline]] inline void pair_words_avx512(const internal::PhiloxRoundKeys& keys,
                                                     std::uint64_t c2, std::uint64_t c3,
                                                     std::uint32_t first, std::uint64_t* a,
                                                     std::uint64_t* b) noexcept {
  static_assert(L % 8 == 0);
  using internal::kPhiloxM0;
  using internal::kPhiloxM1;
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
      const __m512i p0 = internal::mul_epu32_512(m0, _mm512_xor_si512(w1, r0x0_v));  // round 1
      const __m512i y2 = _mm512_xor_si512(internal::srli32_512(p0), k1_1);
      const __m512i p1 = internal::mul_epu32_512(m1, y2);  // round 2
      x0[v] = _mm512_xor_si512(internal::srli32_512(p1), r1x1_k);
      x1[v] = p1;
      x2[v] = _mm512_xor_si512(p0, r2p0_k);
      x3[v] = r2x3;
    }
    internal::philox_rounds_avx512<kV, 3>(keys, x0, x1, x2, x3);
    for (std::size_t v = 0; v < kV; ++v) {
      _mm512_store_si512(a + l + 8 * v,
                         _mm512_ternarylogic_epi64(x0[v], low, internal::slli32_512(x1[v]), 0xEA));
      _mm512_store_si512(b + l + 8 * v,
                         _mm512_ternarylogic_epi64(x2[v], low, internal::slli32_512(x3[v]), 0xEA));
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
  const internal::PhiloxRoundKeys keys =
      internal::philox_round_keys(key_words(seed, 0, purpose).key);
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
    if constexpr (internal::kPhiloxSimdLanes > 0) {
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
        internal::philox4x32_10_simd<kChunk>(keys, w0, w1, w2, w3);
        for (std::size_t l = 0; l < kChunk; ++l) {
          box_muller(w0[l] | w1[l] << 32, w2[l] | w3[l] << 32, out0[at + l], out1[at + l]);
        }
      };
      for (; k + 16 <= n; k += 16) chunk.template operator()<16>(k);
      if constexpr (8 % internal::kPhiloxSimdStep == 0) {
        for (; k + 8 <= n; k += 8) chunk.template operator()<8>(k);
      }
    }
#endif
    for (; k < n; ++k) {
      std::uint64_t x0 = 0;
      std::uint64_t x1 = (first_particle + k) & 0xFFFFFFFFu;
      std::uint64_t x2 = c2;
      std::uint64_t x3 = c3;
      internal::philox4x32_10_words(keys, x0, x1, x2, x3);
      box_muller(x0 | x1 << 32, x2 | x3 << 32, out0[k], out1[k]);
    }
  }
}

}  // namespace

std::array<double, 2> normal_pair_from_bits(std::uint64_t a, std::uint64_t b) noexcept {
  std::array<double, 2> z{};
  box_muller(a, b, z[0], z[1]);
  return z;
}

RandomStream::RandomStream(const StreamKey& key) noexcept : particle_(key.particle) {
  const KeyWords kw = key_words(key.seed, key.step, key.purpose);
  key_ = kw.key;
  step_low_ = kw.step_low;
  step_high_purpose_ = kw.step_high_purpose;
}

void RandomStream::refill(bool with_normals) noexcept {
  assert(next_block_ < (std::uint64_t{1} << 32) && "more than 2^32 blocks drawn from one stream");
  PhiloxLanes<kBufferBlocks> lanes{};
  for (std::size_t l = 0; l < kBufferBlocks; ++l) {
    lanes.x0[l] = (next_block_ + l) & 0xFFFFFFFFu;
    lanes.x1[l] = particle_;
  }
  philox4x32_10_lanes(key_, step_low_, step_high_purpose_, lanes);
  for (std::size_t l = 0; l < kBufferBlocks; ++l) {
    buffer_[4 * l] = static_cast<std::uint32_t>(lanes.x0[l]);
    buffer_[4 * l + 1] = static_cast<std::uint32_t>(lanes.x1[l]);
    buffer_[4 * l + 2] = static_cast<std::uint32_t>(lanes.x2[l]);
    buffer_[4 * l + 3] = static_cast<std::uint32_t>(lanes.x3[l]);
  }
  normals_valid_ = with_normals;
  if (with_normals) {
    alignas(32) double z0[kBufferBlocks];
    alignas(32) double z1[kBufferBlocks];
    LanesToNormals{}(lanes, z0, z1);
    for (std::size_t l = 0; l < kBufferBlocks; ++l) {
      normals_[2 * l] = z0[l];
      normals_[2 * l + 1] = z1[l];
    }
  }
  next_block_ += kBufferBlocks;
  used_ = 0;
}

double RandomStream::normal() noexcept {
  if (has_spare_) {
    has_spare_ = false;
    return spare_normal_;
  }
  if (used_ == kBufferWords) refill(true);
  if (used_ % 4 == 0 && normals_valid_) {  // a whole buffered block: its pair is ready
    const std::size_t pair = used_ / 4;
    used_ += 4;
    spare_normal_ = normals_[2 * pair + 1];
    has_spare_ = true;
    return normals_[2 * pair];
  }
  const std::uint64_t a = next_u64();
  const std::uint64_t b = next_u64();
  double z0 = 0.0;
  box_muller(a, b, z0, spare_normal_);
  has_spare_ = true;
  return z0;
}

void RandomStream::fill_uniform(std::span<double> out) noexcept {
  std::size_t i = 0;
  // Drain the buffer through the scalar path; off a block boundary (an odd word count) the
  // stream never realigns, so it stays scalar.
  while (i < out.size() && used_ != kBufferWords) {
    if (used_ % 2 != 0) {
      for (; i < out.size(); ++i) out[i] = uniform();
      return;
    }
    out[i++] = uniform();
  }
  const std::uint64_t blocks = (out.size() - i) / 2;
  const KeyWords kw{key_, step_low_, step_high_purpose_};
  stream_blocks(kw, particle_, next_block_, blocks, out.data() + i, LanesToUniforms{});
  next_block_ += blocks;
  i += 2 * blocks;
  if (i < out.size()) out[i] = uniform();
}

void RandomStream::fill_normal(std::span<double> out) noexcept {
  std::size_t i = 0;
  // The spare and the buffered pairs first (scalar); a stream off a block boundary never gets
  // back to one (every pair draws four words), so it stays scalar to the end.
  while (i < out.size() && (has_spare_ || used_ != kBufferWords)) out[i++] = normal();
  const std::uint64_t blocks = (out.size() - i) / 2;
  const KeyWords kw{key_, step_low_, step_high_purpose_};
  stream_blocks(kw, particle_, next_block_, blocks, out.data() + i, LanesToNormals{});
  next_block_ += blocks;
  i += 2 * blocks;
  if (i < out.size()) out[i] = normal();  // keeps the sin half as the spare, like normal()
}

void normals_for_particles(std::uint64_t seed, std::uint64_t step, Purpose purpose,
                           std::uint32_t first_particle, std::size_t count,
                           std::size_t per_particle, std::span<double> out) noexcept {
  assert(out.size() == count * per_particle && "out.size() must be count * per_particle");
  particle_blocks(key_words(seed, step, purpose), first_particle, count, per_particle, out.data(),
                  LanesToNormals{});
}

void uniforms_for_particles(std::uint64_t seed, std::uint64_t step, Purpose purpose,
                            std::uint32_t first_particle, std::size_t count,
                            std::size_t per_particle, std::span<double> out) noexcept {
  assert(out.size() == count * per_particle && "out.size() must be count * per_particle");
  particle_blocks(key_words(seed, step, purpose), first_particle, count, per_particle, out.data(),
                  LanesToUniforms{});
}

void normal_pairs_for_particles(std::uint64_t seed, std::uint64_t step, Purpose purpose,
                                std::uint32_t first_particle, std::size_t count,
                                std::span<double> first, std::span<double> second) noexcept {
  normal_pairs_for_particles(seed, std::span(&step, 1), purpose, first_particle, count, first,
                             second, count);
}

void normal_pairs_for_particles(std::uint64_t seed, std::span<const std::uint64_t> steps,
                                Purpose purpose, std::uint32_t first_particle, std::size_t count,
                                std::span<double> first, std::span<double> second,
                                std::size_t stride) noexcept {
  if (steps.empty() || count == 0) return;
  assert(stride >= count && "stride must be at least count");
  assert(first.size() >= (steps.size() - 1) * stride + count &&
         second.size() >= (steps.size() - 1) * stride + count && "outputs too short");
  assert(std::uint64_t{first_particle} + count <= (std::uint64_t{1} << 32) &&
         "first_particle + count must not exceed 2^32");
  pair_run(seed, steps, purpose, first_particle, count, first.data(), second.data(), stride);
}

}  // namespace fastslam::parallel
