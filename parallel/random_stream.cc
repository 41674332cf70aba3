#include "parallel/random_stream.h"

#include <array>
#include <cassert>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

#include "parallel/internal/philox.h"
#include "parallel/internal/random_dispatch.h"
#include "parallel/internal/random_kernels.h"

namespace fastslam::parallel {
namespace {

using internal::box_muller;
using internal::key_words;
using internal::KeyWords;
using internal::philox4x32_10;
using internal::philox4x32_10_lanes;
using internal::PhiloxLanes;
using internal::random_kernels;

// Compile-time self-check against Random123's known-answer vectors (kat_vectors there).
static_assert(philox4x32_10({0, 0, 0, 0}, {0, 0}) ==
              internal::PhiloxCounter{0x6627e8d5u, 0xe169c58du, 0xbc57ac4cu, 0x9b00dbd8u});
static_assert(philox4x32_10({0xffffffffu, 0xffffffffu, 0xffffffffu, 0xffffffffu},
                            {0xffffffffu, 0xffffffffu}) ==
              internal::PhiloxCounter{0x408f276du, 0x41c83b0eu, 0xa20bc7c6u, 0x6d5451fdu});
static_assert(philox4x32_10({0x243f6a88u, 0x85a308d3u, 0x13198a2eu, 0x03707344u},
                            {0xa4093822u, 0x299f31d0u}) ==
              internal::PhiloxCounter{0xd16cfe09u, 0x94fdccebu, 0x5001e420u, 0x24126ea1u});

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
    for (std::size_t l = 0; l < kBufferBlocks; ++l) {
      box_muller(lanes.x0[l] | lanes.x1[l] << 32, lanes.x2[l] | lanes.x3[l] << 32, z0[l], z1[l]);
    }
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
  random_kernels().stream_uniforms(kw, particle_, next_block_, blocks, out.data() + i);
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
  random_kernels().stream_normals(kw, particle_, next_block_, blocks, out.data() + i);
  next_block_ += blocks;
  i += 2 * blocks;
  if (i < out.size()) out[i] = normal();  // keeps the sin half as the spare, like normal()
}

void normals_for_particles(std::uint64_t seed, std::uint64_t step, Purpose purpose,
                           std::uint32_t first_particle, std::size_t count,
                           std::size_t per_particle, std::span<double> out) noexcept {
  assert(out.size() == count * per_particle && "out.size() must be count * per_particle");
  random_kernels().particle_normals(key_words(seed, step, purpose), first_particle, count,
                                    per_particle, out.data());
}

void uniforms_for_particles(std::uint64_t seed, std::uint64_t step, Purpose purpose,
                            std::uint32_t first_particle, std::size_t count,
                            std::size_t per_particle, std::span<double> out) noexcept {
  assert(out.size() == count * per_particle && "out.size() must be count * per_particle");
  random_kernels().particle_uniforms(key_words(seed, step, purpose), first_particle, count,
                                     per_particle, out.data());
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
  random_kernels().normal_pairs(seed, steps, purpose, first_particle, count, first.data(),
                                second.data(), stride);
}

std::string_view random_stream_isa() noexcept { return random_kernels().name; }

}  // namespace fastslam::parallel
