// Deterministic random streams keyed by (seed, step, particle, purpose).
//
// Every random number the filter draws is a pure function of where it is used: the run's seed,
// the control step, the particle and what the draw is for (`Purpose`), plus its position in that
// stream. Nothing is shared between threads and nothing depends on the order in which particles
// are processed, so a run with the same seed is bit-identical for 1, 2 or N threads, any block
// size and any TBB scheduling. There is no global generator anywhere; callers construct a
// `RandomStream` (a value on the stack) or call the batch functions for a block of particles.
//
// Generator: Philox4x32-10 (Salmon, Moraes, Dror, Shaw, SC'11; parallel/internal/philox.h). Why:
//   - counter-based: a block is a pure function f(counter, key), so any (seed, step, particle,
//     purpose, position) is reached in O(1) with no state to share, split or jump ahead - the
//     access pattern of a particle filter processed in parallel blocks in any order;
//   - statistically strong: "Crush-resistant" - the authors report that Philox4x32 passes all of
//     TestU01's SmallCrush, Crush and BigCrush from 7 rounds on (10 is their default, a safety
//     margin), with counters that are incremented in any one word and with many distinct keys,
//     i.e. exactly the structured, neighbouring counters fed here;
//   - cheap: ten rounds of two 32x32->64 multiplies per 128 bits, and independent blocks
//     vectorise side by side (the batch functions do that, 16 blocks at a time).
// A keyed SplitMix/PCG would be as fast, but its quality for highly structured keys (particle k
// vs k + 1, step s vs s + 1) would rest on an ad-hoc mixer; Philox's has been tested for that.
//
// Key layout. Philox key = the 64-bit seed (low word first). Counter words:
//   c0 = block index within the stream (each block = 128 bits = four 32-bit words),
//   c1 = particle, c2 = step bits 0..31, c3 = purpose (8 bits) << 24 | step bits 32..55.
// Limits (REQUIRES, checked by assert in debug builds): step < 2^56; purpose < 256; at most
// 2^32 blocks = 2^34 32-bit words (2^33 uniforms or normals) per stream; for the batch functions
// first_particle + count <= 2^32. Within them, distinct (key, position) pairs are distinct Philox
// inputs (counter, key), so no two draws are ever copies of each other by construction.
//
// Draws. A stream is a sequence of 32-bit words (block b gives words 4b..4b+3).
//   next_u32: the next word. next_u64: the next two words w, w' as w | w' << 32.
//   uniform: next_u64() >> 11 times 2^-53, in [0, 1) (53 random bits; 1.0 is never returned).
//   uniform_pos: (next_u64() >> 11 | 1) times 2^-53, in (0, 1): 52 random bits, odd multiples of
//     2^-53, symmetric about 1/2; never 0 or 1, so log() is safe.
//   normal: Box-Muller. A pair (a, b) = two next_u64() gives r = sqrt(-2 ln u1) with
//     u1 = ((a >> 11) + 1) 2^-53 in (0, 1] and theta = 2 pi (b >> 11) 2^-53; the first normal()
//     returns r cos(theta) and keeps r sin(theta) for the next call. So normal j of a fresh stream
//     comes from block j / 2 alone (cos for even j, sin for odd j): a fixed number of bits per
//     normal, which keeps every draw randomly addressable and lets the batch functions vectorise
//     over blocks. A ziggurat is faster per scalar draw but consumes a variable number of words
//     (rejection), which breaks both properties; vectorised, Box-Muller costs about as much as
//     the Philox block it consumes. |normal()| <= sqrt(2 * 53 ln 2) ~ 8.57.
//   The log, sin and cos are our own (parallel/internal/vmath.h; the pair's error is ~1.5 ulp
//   of max(r, 1), tested against long-double libm): IEEE-754 +, *, / and fma on explicit
//   operations, no libm and nothing for -ffp-contract to fuse; the sqrt is IEEE-754's correctly
//   rounded one (a single instruction: random_stream.cc is compiled with -fno-math-errno, so it
//   vectorises and never calls libm). So the scalar and the vectorised paths give the same bits
//   (tested) and results do not depend on the C library. They do depend on whether the
//   target has a fast fma (a build with -march=native on an FMA machine and a generic x86-64
//   build may differ in the last bits of a normal); words and uniforms are identical everywhere.
//
// Thread safety: `RandomStream` is thread-compatible (a value; use one per task or per
// particle). The batch functions are pure and may run concurrently on disjoint outputs.
// Costs: constructing a stream is O(1) (about 180 bytes, no allocation); a draw is O(1)
// amortised; nothing here allocates. Single thread, AVX-512 (EPYC), g++ 12 -O3 -march=native
// (bench/parallel/random_stream_benchmark.cc): normals_for_particles ~360 M normals/s for an
// even per_particle, from blocks of 8 particles up; normal_pairs_for_particles (Philox and
// Box-Muller fused) ~480 M/s in long runs, ~430 M/s in the filter's shape (blocks of 16
// particles, 9 steps per call); fill_normal ~450 M/s; scalar normal() ~145 M/s. Uniforms: fill
// ~880 M/s, uniforms_for_particles ~540 M/s (per_particle = 4), scalar uniform() ~290 M/s.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>

#include "parallel/internal/philox.h"

namespace fastslam::parallel {

// What a stream is for; part of the key so two uses never share draws. Values must be < 256;
// kUser + i (i < 192) are free for other uses.
enum class Purpose : std::uint32_t {
  kMotion = 1,
  kProposal = 2,
  kAssociation = 3,
  kResample = 4,
  kSimulator = 5,
  kInitial = 6,
  kUser = 64
};

// Where a stream is used. REQUIRES: step < 2^56, purpose < 256.
struct StreamKey {
  std::uint64_t seed = 0;
  std::uint64_t step = 0;
  std::uint32_t particle = 0;
  Purpose purpose = Purpose::kUser;
};

// The conversions behind the draws, for callers (and tests) holding their own 64-bit draws.
// uniform() == uniform_from_bits(next_u64()): the top 53 bits times 2^-53, in [0, 1).
constexpr double uniform_from_bits(std::uint64_t bits) noexcept {
  return static_cast<double>(bits >> 11) * 0x1p-53;
}
// uniform_pos() == uniform_pos_from_bits(next_u64()): odd multiples of 2^-53, in (0, 1).
constexpr double uniform_pos_from_bits(std::uint64_t bits) noexcept {
  return static_cast<double>((bits >> 11) | 1u) * 0x1p-53;
}
// The Box-Muller pair of normal(): a = the first next_u64() of the pair, b = the second;
// returns {r cos(theta), r sin(theta)} (see the header comment). Pure, O(1), no libm.
std::array<double, 2> normal_pair_from_bits(std::uint64_t a, std::uint64_t b) noexcept;

// The counter-based stream of one key. Thread-compatible value type, no allocation.
//
// Internally it generates four Philox blocks at a time side by side (and, when the draw is a
// normal(), their four Box-Muller pairs), which only changes speed, never values: the values are
// those of the word sequence described above, whatever mix of draws is made.
class RandomStream {
 public:
  explicit RandomStream(const StreamKey& key) noexcept;

  std::uint32_t next_u32() noexcept {
    if (used_ == kBufferWords) refill(false);
    return buffer_[used_++];
  }
  std::uint64_t next_u64() noexcept {
    const std::uint64_t low = next_u32();
    return low | std::uint64_t{next_u32()} << 32;
  }
  // [0, 1), 53 random bits.
  double uniform() noexcept { return uniform_from_bits(next_u64()); }
  // (0, 1), never 0 (safe for log) and never 1: odd multiples of 2^-53.
  double uniform_pos() noexcept { return uniform_pos_from_bits(next_u64()); }
  // Standard normal (Box-Muller, see the header comment).
  double normal() noexcept;

  // Same values as out.size() calls of uniform(), resp. normal(), and the same draws afterwards.
  // Vectorised over 16 blocks at a time once the stream sits on a block boundary (a fresh
  // stream, or one whose draws so far filled whole blocks); a stream off a block boundary (an odd
  // number of next_u32() or uniform() calls before fill_normal) stays on the scalar path.
  void fill_uniform(std::span<double> out) noexcept;
  void fill_normal(std::span<double> out) noexcept;

  // 32-bit words drawn so far (a normal() pair draws four, its spare none).
  std::uint64_t words_drawn() const noexcept { return 4 * next_block_ + used_ - kBufferWords; }

 private:
  static constexpr unsigned kBufferBlocks = 4;
  static constexpr unsigned kBufferWords = 4 * kBufferBlocks;

  // Generates blocks next_block_ .. next_block_ + 3 into buffer_ (and, if `with_normals`, their
  // Box-Muller pairs into normals_).
  void refill(bool with_normals) noexcept;

  internal::PhiloxKey key_{};  // the seed
  std::uint32_t particle_ = 0;
  std::uint32_t step_low_ = 0;
  std::uint32_t step_high_purpose_ = 0;
  unsigned used_ = kBufferWords;  // words of buffer_ already drawn; kBufferWords = all
  std::uint64_t next_block_ = 0;  // counter word 0 of the block after the buffered ones
  std::uint32_t buffer_[kBufferWords] = {};
  double normals_[2 * kBufferBlocks] = {};  // pair of buffered block b: normals_[2b], [2b + 1]
  bool normals_valid_ = false;
  bool has_spare_ = false;
  double spare_normal_ = 0.0;  // the sin half of the last Box-Muller pair, if has_spare_
};

// Batches for a block of particles: out[k * per_particle + j] is the j-th normal() of the stream
// {seed, step, first_particle + k, purpose}, so results do not depend on how particles are blocked.
// REQUIRES: out.size() == count * per_particle; first_particle + count <= 2^32.
// Costs: O(count * per_particle), vectorised over 16 Philox blocks at a time; no allocation.
void normals_for_particles(std::uint64_t seed, std::uint64_t step, Purpose purpose,
                           std::uint32_t first_particle, std::size_t count,
                           std::size_t per_particle, std::span<double> out) noexcept;
// The same for per_particle = 2, one column per draw: first[k] and second[k] are the first and
// second normal() of particle first_particle + k's stream (the cos and sin halves of its first
// Box-Muller pair), i.e. out[2k] and out[2k + 1] of normals_for_particles(..., 2, out). For
// kernels that read the two normals of a particle block as separate columns (motion sampling).
// REQUIRES: first.size() >= count, second.size() >= count; first_particle + count <= 2^32.
// Costs: O(count); Philox and Box-Muller fused in one vectorised loop over the particles.
void normal_pairs_for_particles(std::uint64_t seed, std::uint64_t step, Purpose purpose,
                                std::uint32_t first_particle, std::size_t count,
                                std::span<double> first, std::span<double> second) noexcept;
// The same for several steps in one call: for each j, first[j * stride + k] and
// second[j * stride + k] are the first two normals of the stream {seed, steps[j],
// first_particle + k, purpose}. One call per particle block and scan covers every control.
// REQUIRES: stride >= count; first and second hold (steps.size() - 1) * stride + count values;
// first_particle + count <= 2^32.
void normal_pairs_for_particles(std::uint64_t seed, std::span<const std::uint64_t> steps,
                                Purpose purpose, std::uint32_t first_particle, std::size_t count,
                                std::span<double> first, std::span<double> second,
                                std::size_t stride) noexcept;
// The same for uniform(): out[k * per_particle + j] is the j-th uniform() of particle
// first_particle + k's stream.
void uniforms_for_particles(std::uint64_t seed, std::uint64_t step, Purpose purpose,
                            std::uint32_t first_particle, std::size_t count,
                            std::size_t per_particle, std::span<double> out) noexcept;

}  // namespace fastslam::parallel
