// Deterministic random streams keyed by (seed, step, particle, purpose): every draw is a pure
// function of where it is used, so a run is bit-identical for any thread count and schedule.
// No global generator: callers construct a RandomStream (a value) or call the batch functions
// for a block of particles. Generator: Philox4x32-10 (Salmon et al., SC'11;
// internal/philox.h); uniforms from 53 bits, normals by Box-Muller with our own log, sin and
// cos (internal/vmath.h), so scalar and vectorised paths give the same bits. Key layout,
// limits, draw definitions and the generator's choice: docs/parallel.md.
// REQUIRES: step < 2^56, purpose < 256, at most 2^32 blocks per stream, first_particle + count
// <= 2^32 for the batch functions.
// Thread safety: RandomStream is thread-compatible (one per task or particle); the batch
// functions are pure and may run concurrently on disjoint outputs.
// Costs: constructing a stream O(1); a draw O(1) amortised; nothing allocates.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

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
  kMotionRun = 7,         // the composed motion draw's first two normals (engine/motion_run.h)
  kMotionRunHeading = 8,  // and its third
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

// The instruction set the batch functions (and fill_uniform, fill_normal) run on in this
// process. A portable build (FASTSLAM_PORTABLE, README.md) has "baseline", "avx2" (x86-64-v3)
// and "avx512" (x86-64-v4) kernels and uses the best this CPU runs, or the one the environment
// variable FASTSLAM_ISA names (read once, at the first batch call; a name it cannot honour is
// reported on stderr and the best is used); all give the same values. Other builds have one,
// "native", compiled for the build's own flags, and ignore FASTSLAM_ISA.
// Thread-safe; the first call reads the CPU's features, later calls are O(1).
std::string_view random_stream_isa() noexcept;

}  // namespace fastslam::parallel
