// Philox4x32-10 (Salmon, Moraes, Dror, Shaw, SC'11; Random123's philox.h), the counter-based
// generator behind parallel/random_stream.h (not API): a block is a pure function of a 128-bit
// counter and a 64-bit key. Four forms, bit-identical by construction (random_stream_test
// checks Random123's known answers): philox4x32_10 (one block, constexpr),
// philox4x32_10_lanes<L> (plain loops that vectorise), philox4x32_10_words (one block inline in
// a caller's loop), philox4x32_10_simd<L> (explicit AVX-512 / AVX2 multiplies). What the
// kernels call is always inlined: random_kernels.cc is compiled once per instruction set, and an
// out-of-line copy from its AVX-512 compilation could be the one the linker keeps for all.
// Thread safety: pure functions. Costs: O(1) per block, no allocation.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#if defined(__AVX2__)
#include <immintrin.h>
#endif

namespace fastslam::parallel::internal {

inline constexpr std::uint32_t kPhiloxM0 = 0xD2511F53u;  // round multipliers
inline constexpr std::uint32_t kPhiloxM1 = 0xCD9E8D57u;
inline constexpr std::uint32_t kPhiloxW0 = 0x9E3779B9u;  // key bumps: golden ratio,
inline constexpr std::uint32_t kPhiloxW1 = 0xBB67AE85u;  // sqrt(3) - 1
inline constexpr int kPhiloxRounds = 10;

using PhiloxCounter = std::array<std::uint32_t, 4>;
using PhiloxKey = std::array<std::uint32_t, 2>;

// One Philox4x32-10 block: Random123's philox4x32(ctr, key) with 10 rounds.
constexpr PhiloxCounter philox4x32_10(PhiloxCounter ctr, PhiloxKey key) noexcept {
  for (int round = 0; round < kPhiloxRounds; ++round) {
    if (round > 0) {
      key[0] += kPhiloxW0;
      key[1] += kPhiloxW1;
    }
    const std::uint64_t p0 = std::uint64_t{kPhiloxM0} * ctr[0];
    const std::uint64_t p1 = std::uint64_t{kPhiloxM1} * ctr[2];
    ctr = {static_cast<std::uint32_t>(p1 >> 32) ^ ctr[1] ^ key[0], static_cast<std::uint32_t>(p1),
           static_cast<std::uint32_t>(p0 >> 32) ^ ctr[3] ^ key[1], static_cast<std::uint32_t>(p0)};
  }
  return ctr;
}

// The ten round keys of a key (the Weyl sequence of Random123's philox4x32 bumpkey).
struct PhiloxRoundKeys {
  std::uint64_t k0[kPhiloxRounds];
  std::uint64_t k1[kPhiloxRounds];
};
[[gnu::always_inline]] constexpr PhiloxRoundKeys philox_round_keys(PhiloxKey key) noexcept {
  PhiloxRoundKeys keys{};
  for (int round = 0; round < kPhiloxRounds; ++round) {
    keys.k0[round] = key[0];
    keys.k1[round] = key[1];
    key[0] += kPhiloxW0;
    key[1] += kPhiloxW1;
  }
  return keys;
}

// Explicit SIMD rounds. A round multiplies 32-bit words; written in plain C++ on words held in
// 64-bit lanes that is a 64 x 64-bit product, which AVX2 has no instruction for (its emulation
// costs three vpmuludq, so GCC 12 keeps those loops scalar) and which AVX-512DQ does with
// vpmullq, a slower instruction than needed. vpmuludq (_mm256/_mm512_mul_epu32) multiplies
// exactly the low 32 bits of each 64-bit lane, which is the round's 32x32->64 product, so the
// words are the portable code's (tests/parallel/random_stream_test.cc compares them).
// AVX-512 does not mask the words between rounds: a product's high half is garbage above the
// low 32 bits of x1 and x3, which only ever meet xors (into the low halves of x0 and x2, whose
// high halves then carry garbage too) and vpmuludq, which ignores high halves; the stores mask
// once. It runs two 8-lane vectors side by side (two independent dependency chains).
// kPhiloxSimdLanes is the vector width in lanes, 0 where unused.
#if defined(__AVX512F__)
inline constexpr std::size_t kPhiloxSimdLanes = 8;
#elif defined(__AVX2__)
inline constexpr std::size_t kPhiloxSimdLanes = 4;
#else
inline constexpr std::size_t kPhiloxSimdLanes = 0;
#endif
inline constexpr std::size_t kPhiloxSimdStep = kPhiloxSimdLanes > 0 ? kPhiloxSimdLanes : 1;

#if defined(__AVX512F__)
// vpmuludq, vpsrlq, vpsllq in their zero-masking forms with every lane selected (the same
// instructions): GCC 12 reports a false -Wmaybe-uninitialized inside the unmasked intrinsics.
[[gnu::always_inline]] inline __m512i mul_epu32_512(__m512i a, __m512i b) noexcept {
  return _mm512_maskz_mul_epu32(0xFF, a, b);
}
[[gnu::always_inline]] inline __m512i srli32_512(__m512i a) noexcept {
  return _mm512_maskz_srli_epi64(0xFF, a, 32);
}
[[gnu::always_inline]] inline __m512i slli32_512(__m512i a) noexcept {
  return _mm512_maskz_slli_epi64(0xFF, a, 32);
}

// `V` vectors of 8 lanes through rounds kFirstRound .. 9 (all ten by default), in registers
// (see above: the words' high halves are garbage on exit).
template <std::size_t V, int kFirstRound = 0>
[[gnu::always_inline]] inline void philox_rounds_avx512(const PhiloxRoundKeys& keys, __m512i* a0,
                                                        __m512i* a1, __m512i* a2,
                                                        __m512i* a3) noexcept {
  const __m512i m0 = _mm512_set1_epi64(kPhiloxM0);
  const __m512i m1 = _mm512_set1_epi64(kPhiloxM1);
#pragma GCC unroll 10
  for (int round = kFirstRound; round < kPhiloxRounds; ++round) {
    const __m512i k0 = _mm512_set1_epi64(static_cast<long long>(keys.k0[round]));
    const __m512i k1 = _mm512_set1_epi64(static_cast<long long>(keys.k1[round]));
#pragma GCC unroll 4
    for (std::size_t v = 0; v < V; ++v) {
      const __m512i p0 = mul_epu32_512(m0, a0[v]);
      const __m512i p1 = mul_epu32_512(m1, a2[v]);
      const __m512i n0 = _mm512_ternarylogic_epi64(srli32_512(p1), a1[v], k0, 0x96);  // xor
      const __m512i n2 = _mm512_ternarylogic_epi64(srli32_512(p0), a3[v], k1, 0x96);
      a1[v] = p1;
      a3[v] = p0;
      a0[v] = n0;
      a2[v] = n2;
    }
  }
}
#endif

template <std::size_t L>
[[gnu::always_inline]] inline void philox4x32_10_simd(const PhiloxRoundKeys& keys,
                                                      std::uint64_t* x0, std::uint64_t* x1,
                                                      std::uint64_t* x2,
                                                      std::uint64_t* x3) noexcept {
#if defined(__AVX512F__)
  static_assert(L % kPhiloxSimdLanes == 0);
  const auto load = [](const std::uint64_t* p) { return _mm512_loadu_si512(p); };
  const auto store = [](std::uint64_t* p, __m512i v) {
    _mm512_storeu_si512(p, _mm512_and_si512(v, _mm512_set1_epi64(0xFFFFFFFFu)));
  };
  constexpr std::size_t kPair = 2 * kPhiloxSimdLanes;
  std::size_t l = 0;
  for (; l + kPair <= L; l += kPair) {
    __m512i a0[2] = {load(x0 + l), load(x0 + l + 8)};
    __m512i a1[2] = {load(x1 + l), load(x1 + l + 8)};
    __m512i a2[2] = {load(x2 + l), load(x2 + l + 8)};
    __m512i a3[2] = {load(x3 + l), load(x3 + l + 8)};
    philox_rounds_avx512<2>(keys, a0, a1, a2, a3);
    for (std::size_t v = 0; v < 2; ++v) {
      store(x0 + l + 8 * v, a0[v]);
      store(x1 + l + 8 * v, a1[v]);
      store(x2 + l + 8 * v, a2[v]);
      store(x3 + l + 8 * v, a3[v]);
    }
  }
  if constexpr (L % kPair != 0) {
    __m512i a0[1] = {load(x0 + l)};
    __m512i a1[1] = {load(x1 + l)};
    __m512i a2[1] = {load(x2 + l)};
    __m512i a3[1] = {load(x3 + l)};
    philox_rounds_avx512<1>(keys, a0, a1, a2, a3);
    store(x0 + l, a0[0]);
    store(x1 + l, a1[0]);
    store(x2 + l, a2[0]);
    store(x3 + l, a3[0]);
  }
#elif defined(__AVX2__)
  static_assert(L % kPhiloxSimdLanes == 0);
  using V = __m256i;
  const auto load = [](const std::uint64_t* p) {
    return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p));
  };
  const auto splat = [](std::uint64_t v) { return _mm256_set1_epi64x(static_cast<long long>(v)); };
  const V m0 = splat(kPhiloxM0);
  const V m1 = splat(kPhiloxM1);
  const V low = splat(0xFFFFFFFFu);
  for (std::size_t l = 0; l < L; l += kPhiloxSimdLanes) {
    V a0 = load(x0 + l);
    V a1 = load(x1 + l);
    V a2 = load(x2 + l);
    V a3 = load(x3 + l);
#pragma GCC unroll 10
    for (int round = 0; round < kPhiloxRounds; ++round) {
      const V p0 = _mm256_mul_epu32(m0, a0);
      const V p1 = _mm256_mul_epu32(m1, a2);
      const V n0 =
          _mm256_xor_si256(_mm256_xor_si256(_mm256_srli_epi64(p1, 32), a1), splat(keys.k0[round]));
      const V n2 =
          _mm256_xor_si256(_mm256_xor_si256(_mm256_srli_epi64(p0, 32), a3), splat(keys.k1[round]));
      a1 = _mm256_and_si256(p1, low);
      a3 = _mm256_and_si256(p0, low);
      a0 = n0;
      a2 = n2;
    }
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(x0 + l), a0);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(x1 + l), a1);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(x2 + l), a2);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(x3 + l), a3);
  }
#else
  // Not used on these targets (kPhiloxSimdLanes == 0); the same words, block by block.
  constexpr std::uint64_t kLow = 0xFFFFFFFFu;
  for (std::size_t l = 0; l < L; ++l) {
#pragma GCC unroll 10
    for (int round = 0; round < kPhiloxRounds; ++round) {
      const std::uint64_t p0 = std::uint64_t{kPhiloxM0} * x0[l];
      const std::uint64_t p1 = std::uint64_t{kPhiloxM1} * x2[l];
      const std::uint64_t n0 = (p1 >> 32) ^ x1[l] ^ keys.k0[round];
      const std::uint64_t n2 = (p0 >> 32) ^ x3[l] ^ keys.k1[round];
      x1[l] = p1 & kLow;
      x3[l] = p0 & kLow;
      x0[l] = n0;
      x2[l] = n2;
    }
  }
#endif
}

// L blocks side by side. Word w of lane l is x<w>[l]; every value is below 2^32.
template <std::size_t L>
struct PhiloxLanes {
  alignas(64) std::uint64_t x0[L];
  alignas(64) std::uint64_t x1[L];
  alignas(64) std::uint64_t x2[L];
  alignas(64) std::uint64_t x3[L];
};

// On entry lanes.x0[l], lanes.x1[l] are counter words 0 and 1 of lane l (below 2^32); counter
// words 2 and 3 are `c2`, `c3` in every lane. On exit lanes holds the L output blocks:
// lanes.x<w>[l] == philox4x32_10({x0[l], x1[l], c2, c3}, key)[w].
template <std::size_t L>
[[gnu::always_inline]] inline void philox4x32_10_lanes(PhiloxKey key, std::uint32_t c2,
                                                       std::uint32_t c3,
                                                       PhiloxLanes<L>& lanes) noexcept {
  constexpr std::uint64_t kLow = 0xFFFFFFFFu;
  for (std::size_t l = 0; l < L; ++l) {
    lanes.x2[l] = c2;
    lanes.x3[l] = c3;
  }
  if constexpr (kPhiloxSimdLanes > 0 && L % kPhiloxSimdStep == 0) {
    philox4x32_10_simd<L>(philox_round_keys(key), lanes.x0, lanes.x1, lanes.x2, lanes.x3);
    return;
  }
  std::uint64_t k0 = key[0];
  std::uint64_t k1 = key[1];
#pragma GCC unroll 10
  for (int round = 0; round < kPhiloxRounds; ++round) {
    for (std::size_t l = 0; l < L; ++l) {
      const std::uint64_t p0 = std::uint64_t{kPhiloxM0} * lanes.x0[l];
      const std::uint64_t p1 = std::uint64_t{kPhiloxM1} * lanes.x2[l];
      const std::uint64_t n0 = (p1 >> 32) ^ lanes.x1[l] ^ k0;
      const std::uint64_t n2 = (p0 >> 32) ^ lanes.x3[l] ^ k1;
      lanes.x1[l] = p1 & kLow;
      lanes.x3[l] = p0 & kLow;
      lanes.x0[l] = n0;
      lanes.x2[l] = n2;
    }
    k0 = (k0 + kPhiloxW0) & kLow;
    k1 = (k1 + kPhiloxW1) & kLow;
  }
}

// One block in place: on entry x0..x3 are the counter words (each below 2^32), on exit the
// output words: x<w> == philox4x32_10({x0, x1, x2, x3}, key)[w] for keys ==
// philox_round_keys(key).
[[gnu::always_inline]] inline void philox4x32_10_words(const PhiloxRoundKeys& keys,
                                                       std::uint64_t& x0, std::uint64_t& x1,
                                                       std::uint64_t& x2,
                                                       std::uint64_t& x3) noexcept {
  constexpr std::uint64_t kLow = 0xFFFFFFFFu;
#pragma GCC unroll 10
  for (int round = 0; round < kPhiloxRounds; ++round) {
    const std::uint64_t p0 = std::uint64_t{kPhiloxM0} * x0;
    const std::uint64_t p1 = std::uint64_t{kPhiloxM1} * x2;
    const std::uint64_t n0 = (p1 >> 32) ^ x1 ^ keys.k0[round];
    const std::uint64_t n2 = (p0 >> 32) ^ x3 ^ keys.k1[round];
    x1 = p1 & kLow;
    x3 = p0 & kLow;
    x0 = n0;
    x2 = n2;
  }
}

}  // namespace fastslam::parallel::internal
