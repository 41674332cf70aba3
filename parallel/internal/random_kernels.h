// The batch kernels behind parallel/random_stream.h (not API), and what they share with the
// scalar draws of random_stream.cc: a stream's key words and the Box-Muller transform.
// random_kernels.cc holds the kernels and is compiled once per instruction set, each copy in its
// own namespace kernels_<name> with one table of entry points (RandomKernels): a portable build
// (FASTSLAM_PORTABLE, parallel/CMakeLists.txt) has baseline, avx2 (x86-64-v3) and avx512
// (x86-64-v4) copies and random_dispatch.h picks one at run time; a build tuned for its own
// machine has one copy, native, compiled with the build's flags. Every copy gives the bits of
// the scalar definitions below (tests/parallel/internal/random_dispatch_test.cc).
// Everything here is inline and always inlined: a copy compiled for AVX-512 must not leave an
// out-of-line function that the linker could pick for baseline callers (the symbol check in
// tests/parallel/CMakeLists.txt looks for any).
// Thread safety: pure functions; the tables are constants. Costs: O(1) per block; no allocation.
#pragma once

#include <bit>
#include <cassert>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

#include "parallel/internal/philox.h"
#include "parallel/internal/vmath.h"
#include "parallel/random_stream.h"

namespace fastslam::parallel::internal {

// The key and the fixed counter words of a stream (docs/parallel.md, key layout).
struct KeyWords {
  PhiloxKey key;
  std::uint32_t step_low;
  std::uint32_t step_high_purpose;
};

[[gnu::always_inline]] inline KeyWords key_words(std::uint64_t seed, std::uint64_t step,
                                                 Purpose purpose) noexcept {
  assert(step < (std::uint64_t{1} << 56) && "step must be below 2^56");
  assert(static_cast<std::uint32_t>(purpose) < 256 && "purpose must be below 256");
  return {{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32)},
          static_cast<std::uint32_t>(step),
          (static_cast<std::uint32_t>(purpose) & 0xFFu) << 24 |
              (static_cast<std::uint32_t>(step >> 32) & 0xFFFFFFu)};
}

// Floating point: log and sin/cos of vmath.h, written so that the scalar and the vectorised
// paths give the same bits (see there), and std::sqrt, correctly rounded, which -fno-math-errno
// (parallel/CMakeLists.txt, on the files that call box_muller) turns into one instruction in both
// paths (with errno semantics it would not vectorise; the argument is never negative anyway, so
// errno is never set). random_stream_test checks the composite Box-Muller pair (within 8 ulp of
// max(r, 1)).

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

// Box-Muller on two 64-bit draws (parallel/random_stream.h).
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

// The entry points of one copy of the kernels. The callers in random_stream.cc check the
// REQUIRES of the public functions.
struct RandomKernels {
  std::string_view name;  // "baseline", "avx2", "avx512" or "native"
  // Blocks first_block .. first_block + blocks - 1 of one particle's stream, two values per
  // block (its Box-Muller pair, resp. its two uniforms) to out[0 .. 2 * blocks).
  void (*stream_normals)(const KeyWords& kw, std::uint32_t particle, std::uint64_t first_block,
                         std::uint64_t blocks, double* out) noexcept = nullptr;
  void (*stream_uniforms)(const KeyWords& kw, std::uint32_t particle, std::uint64_t first_block,
                          std::uint64_t blocks, double* out) noexcept = nullptr;
  // normals_for_particles, resp. uniforms_for_particles, on the key words of (seed, step,
  // purpose).
  void (*particle_normals)(const KeyWords& kw, std::uint32_t first_particle, std::size_t count,
                           std::size_t per_particle, double* out) noexcept = nullptr;
  void (*particle_uniforms)(const KeyWords& kw, std::uint32_t first_particle, std::size_t count,
                            std::size_t per_particle, double* out) noexcept = nullptr;
  // normal_pairs_for_particles with several steps (count >= 1, steps not empty).
  void (*normal_pairs)(std::uint64_t seed, std::span<const std::uint64_t> steps, Purpose purpose,
                       std::uint32_t first_particle, std::size_t count, double* first,
                       double* second, std::size_t stride) noexcept = nullptr;
};

}  // namespace fastslam::parallel::internal
