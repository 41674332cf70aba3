#include "parallel/resample.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>

#include "parallel/internal/exp.h"
#include "parallel/random_stream.h"

namespace fastslam::parallel {
namespace {

constexpr std::size_t kBlock = ParticleKernel::kReduceBlock;
static_assert((kBlock & (kBlock - 1)) == 0, "the scan block is a power of two");
constexpr std::size_t kNone = std::numeric_limits<std::size_t>::max();
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr std::size_t kMaxParticles = std::numeric_limits<std::uint32_t>::max();

std::size_t blocks_of(std::size_t n) noexcept { return n / kBlock + (n % kBlock != 0 ? 1 : 0); }

void check_particle_count(std::size_t m) {
  if (m == 0) {
    throw std::invalid_argument("resample: there are no particles (no log-weights)");
  }
  if (m > kMaxParticles) {
    throw std::length_error("resample: " + std::to_string(m) +
                            " particles exceed the 32-bit index limit of " +
                            std::to_string(kMaxParticles));
  }
}

void check_draw_count(std::size_t n) {
  if (n > kMaxParticles) {
    throw std::length_error("resample: " + std::to_string(n) +
                            " draws exceed the 32-bit index limit of " +
                            std::to_string(kMaxParticles));
  }
}

[[noreturn]] void throw_bad_weight(std::size_t particle, double value) {
  throw std::invalid_argument("resample: particle " + std::to_string(particle) +
                              " has log-weight " + (std::isnan(value) ? "NaN" : "+inf") +
                              "; log-weights must be finite or -inf");
}

[[noreturn]] void throw_all_zero(std::size_t m) {
  throw std::domain_error("resample: all " + std::to_string(m) +
                          " particles have log-weight -inf (every weight is zero); "
                          "nothing to draw from");
}

// --- Per-block arithmetic. Out of line so that every caller runs the same instructions (no
// caller-specific floating-point contraction), whichever thread calls it. ---

struct BlockCheck {
  double max = -kInf;
  std::size_t bad = kNone;  // first particle with a NaN or +inf log-weight
};

[[gnu::noinline]] BlockCheck check_block(const double* log_weight, std::size_t begin,
                                         std::size_t end) noexcept {
  BlockCheck result;
  bool any_bad = false;
  for (std::size_t i = begin; i < end; ++i) {
    const double v = log_weight[i];
    result.max = v > result.max ? v : result.max;
    any_bad |= !(v < kInf);  // NaN or +inf
  }
  if (any_bad) {
    for (std::size_t i = begin; i < end; ++i) {
      if (!(log_weight[i] < kInf)) {
        result.bad = i;
        break;
      }
    }
  }
  return result;
}

BlockCheck combine_checks(const BlockCheck& a, const BlockCheck& b) noexcept {
  return {b.max > a.max ? b.max : a.max, a.bad != kNone ? a.bad : b.bad};
}

// The first bad particle, or the maximum; throws on degenerate input.
double checked_max(const BlockCheck& check, std::span<const double> log_weight) {
  if (check.bad != kNone) {
    throw_bad_weight(check.bad, log_weight[check.bad]);
  }
  if (check.max == -kInf) {
    throw_all_zero(log_weight.size());
  }
  return check.max;
}

struct BlockSums {
  double sum = 0.0;     // sum of e_i = exp(l_i - max)
  double square = 0.0;  // sum of e_i^2
};

// e_i = exp(l_i - max); prefix[i] = running sum of e within the block, from 0. Two loops: the
// exponentials vectorise, the running sums are sequential by definition.
[[gnu::noinline]] BlockSums exp_prefix_block(const double* log_weight, double max, double* prefix,
                                             std::size_t begin, std::size_t end) noexcept {
  for (std::size_t i = begin; i < end; ++i) {
    prefix[i] = internal::exp_nonpositive(log_weight[i] - max);
  }
  BlockSums sums;
  for (std::size_t i = begin; i < end; ++i) {
    const double e = prefix[i];
    sums.sum += e;
    sums.square = std::fma(e, e, sums.square);
    prefix[i] = sums.sum;
  }
  return sums;
}

// E_j = -log(1 - u_j) for j in [begin, end) from the streams (seed, step, j, kResample);
// prefix[j] = running sum within the block, from 0. Returns the block's sum.
[[gnu::noinline]] double spacing_prefix_block(std::uint64_t seed, std::uint64_t step,
                                              double* prefix, std::size_t begin,
                                              std::size_t end) noexcept {
  double u[kBlock];
  const std::size_t n = end - begin;
  uniforms_for_particles(seed, step, Purpose::kResample, static_cast<std::uint32_t>(begin), n, 1,
                         std::span<double>(u, n));
  double sum = 0.0;
  for (std::size_t j = 0; j < n; ++j) {
    sum += -std::log1p(-u[j]);
    prefix[begin + j] = sum;
  }
  return sum;
}

struct PoseSums {
  double w = 0.0, x = 0.0, y = 0.0, c = 0.0, s = 0.0;
};

// Weighted sums of x, y, cos theta, sin theta with weights e_i = exp(l_i - max).
[[gnu::noinline]] PoseSums pose_block(const double* log_weight, double max, const double* x,
                                      const double* y, const double* theta, std::size_t begin,
                                      std::size_t end) noexcept {
  PoseSums sums;
  for (std::size_t i = begin; i < end; ++i) {
    const double e = internal::exp_nonpositive(log_weight[i] - max);
    sums.w += e;
    sums.x = std::fma(e, x[i], sums.x);
    sums.y = std::fma(e, y[i], sums.y);
    sums.c = std::fma(e, std::cos(theta[i]), sums.c);
    sums.s = std::fma(e, std::sin(theta[i]), sums.s);
  }
  return sums;
}

// The blocked cumulative weights C_i = O_{i / K} + L_i.
struct Cumulative {
  const double* prefix;
  const double* offset;
  std::size_t size;
  double at(std::size_t i) const noexcept { return offset[i / kBlock] + prefix[i]; }
  // The first i with C_i > t (size when none).
  std::size_t first_above(double t) const noexcept {
    std::size_t lo = 0, hi = size;
    while (lo < hi) {
      const std::size_t mid = lo + (hi - lo) / 2;
      if (at(mid) > t) {
        hi = mid;
      } else {
        lo = mid + 1;
      }
    }
    return lo;
  }
  // The first i with C_i >= t (size when none).
  std::size_t first_at_least(double t) const noexcept {
    std::size_t lo = 0, hi = size;
    while (lo < hi) {
      const std::size_t mid = lo + (hi - lo) / 2;
      if (at(mid) >= t) {
        hi = mid;
      } else {
        lo = mid + 1;
      }
    }
    return lo;
  }
};

// --- The merge. Pointer models: the targets t_k = p_k * T of one scheme, on one output chunk.
// A model is loaded one run [r0, r1) of at most kBlock pointers at a time. ---

template <class P>
concept PointerModel = requires(P& p, const P& cp, std::size_t k, double c) {
  // Makes target(k) valid for k in [r0, r1) (r1 - r0 <= kBlock); runs ascend within a chunk.
  p.load(k, k);
  // t_k for a loaded k; non-decreasing in k.
  { cp.target(k) } -> std::same_as<double>;
  // t_k for any k (may be slower): used once per output chunk, for the pointer before it.
  { cp.target_anywhere(k) } -> std::same_as<double>;
  // A guess of the first loaded k with t_k >= c, given the previous answer in this run (the
  // answers ascend); any value is corrected, a good one saves the correction steps.
  { cp.estimate(c, k) } -> std::convertible_to<double>;
};

// Systematic: t_k = (k + u) * scale; the first k with t_k >= c is ceil(c / scale - u) up to
// rounding, so each particle costs O(1) and no data-dependent branch.
struct SystematicPointers {
  double u, scale, inverse_scale;
  void load(std::size_t, std::size_t) noexcept {}
  double target(std::size_t k) const noexcept { return (static_cast<double>(k) + u) * scale; }
  double target_anywhere(std::size_t k) const noexcept { return target(k); }
  double estimate(double c, std::size_t) const noexcept { return std::ceil(c * inverse_scale - u); }
};

// Stratified: t_k = (k + u_k) * scale, the u_k generated per run from the streams of the
// pointers' indices. The answer is floor(c / scale) or one more.
struct StratifiedPointers {
  std::uint64_t seed = 0, step = 0;
  double scale = 0.0, inverse_scale = 0.0;
  std::size_t r0 = 0;
  double u[kBlock];  // of pointers r0, r0 + 1, ...; filled by load
  void load(std::size_t first, std::size_t last) noexcept {
    r0 = first;
    uniforms_for_particles(seed, step, Purpose::kResample, static_cast<std::uint32_t>(first),
                           last - first, 1, std::span<double>(u, last - first));
  }
  double target(std::size_t k) const noexcept {
    return (static_cast<double>(k) + u[k - r0]) * scale;
  }
  double target_anywhere(std::size_t k) const noexcept {
    RandomStream stream(StreamKey{seed, step, static_cast<std::uint32_t>(k), Purpose::kResample});
    return (static_cast<double>(k) + stream.uniform()) * scale;
  }
  double estimate(double c, std::size_t) const noexcept { return std::floor(c * inverse_scale); }
};

// Multinomial: t_k = G_k * scale from the scanned exponential spacings. No closed-form inverse:
// the guess is the previous answer, so the correction walks forward (the textbook merge).
struct MultinomialPointers {
  const double* prefix;
  const double* offset;
  double scale;
  void load(std::size_t, std::size_t) noexcept {}
  double target(std::size_t k) const noexcept { return (offset[k / kBlock] + prefix[k]) * scale; }
  double target_anywhere(std::size_t k) const noexcept { return target(k); }
  double estimate(double, std::size_t previous) const noexcept {
    return static_cast<double>(previous);
  }
};

static_assert(PointerModel<SystematicPointers> && PointerModel<StratifiedPointers> &&
              PointerModel<MultinomialPointers>);

// The merge of output chunk [k0, k1): out[k] = min(#{i : C_i <= t_k}, top), which is the first i
// with C_i > t_k while t_k < T (C is non-decreasing) and `top` = the first i with C_i == T once
// rounding gives t_k >= T. Computed by counting rather than walking: each particle i whose
// answer K_i = min{k : t_k >= C_i} falls in the run marks it, and a running sum of the marks gives
// the counts. Particles are visited in order, so the run's particles are found without search
// (one binary search per chunk, for the first). Every step is exact, so the result does not
// depend on how outputs are cut into chunks.
template <PointerModel Pointers>
void merge_chunk(const Cumulative& c, std::uint32_t top, Pointers& pointers, std::uint32_t* out,
                 std::size_t k0, std::size_t k1) {
  const std::size_t m = c.size;
  // The first particle whose answer is >= k0: C_i > t_{k0 - 1}.
  std::size_t i = k0 == 0 ? 0 : c.first_above(pointers.target_anywhere(k0 - 1));
  std::uint32_t marks[kBlock];
  for (std::size_t r0 = k0; r0 < k1; r0 += kBlock) {
    const std::size_t r1 = std::min(k1, r0 + kBlock);
    pointers.load(r0, r1);
    std::fill(marks, marks + (r1 - r0), 0u);
    const std::size_t count_before = i;
    const double last = pointers.target(r1 - 1);
    std::size_t k = r0;
    // Particles with C_i in (t_{r0 - 1}, t_{r1 - 1}]: their answers lie in [r0, r1).
    for (double ci; i < m && (ci = c.at(i)) <= last; ++i) {
      const double guess = pointers.estimate(ci, k);
      k = guess <= static_cast<double>(r0)       ? r0
          : guess >= static_cast<double>(r1 - 1) ? r1 - 1
                                                 : static_cast<std::size_t>(guess);
      while (k > r0 && pointers.target(k - 1) >= ci) --k;
      while (pointers.target(k) < ci) ++k;  // stops at r1 - 1: t_{r1 - 1} >= C_i
      ++marks[k - r0];
    }
    std::size_t count = count_before;
    for (std::size_t j = r0; j < r1; ++j) {
      count += marks[j - r0];
      out[j] = static_cast<std::uint32_t>(std::min<std::size_t>(count, top));
    }
  }
}

void subtract_in_place(std::span<double> log_weight, double value, const ParticleKernel& kernel,
                       std::size_t grain) {
  kernel.for_each_block(
      log_weight.size(),
      [&](std::size_t begin, std::size_t end) {
        for (std::size_t i = begin; i < end; ++i) {
          log_weight[i] -= value;
        }
      },
      grain);
}

void fill_in_place(std::span<double> log_weight, double value, const ParticleKernel& kernel,
                   std::size_t grain) {
  kernel.for_each_block(
      log_weight.size(),
      [&](std::size_t begin, std::size_t end) {
        std::fill(log_weight.begin() + static_cast<std::ptrdiff_t>(begin),
                  log_weight.begin() + static_cast<std::ptrdiff_t>(end), value);
      },
      grain);
}

}  // namespace

void validate(const ResamplePolicy& policy) {
  if (!(policy.ess_fraction >= 0.0 && policy.ess_fraction <= 1.0)) {
    throw std::invalid_argument("ResamplePolicy: ess_fraction = " +
                                std::to_string(policy.ess_fraction) + " is not in [0, 1]");
  }
}

bool should_resample(const ResamplePolicy& policy, double ess, std::size_t particles) noexcept {
  if (policy.when == ResamplePolicy::When::kEveryStep) {
    return true;
  }
  return ess < policy.ess_fraction * static_cast<double>(particles);
}

Resampler::Resampler(ResamplePolicy policy, const ParticleKernel& kernel, std::size_t grain)
    : policy_(policy), kernel_(&kernel), grain_(grain) {
  validate(policy_);
}

WeightSummary Resampler::summarize(std::span<const double> log_weight) {
  return summarize(log_weight, SharedSet{});
}

WeightSummary Resampler::summarize(std::span<const double> log_weight, const SharedSet& set) {
  particles_ = 0;
  const std::size_t m = log_weight.size();
  check_particle_count(m);
  Collective* const group = set.group;
  const std::size_t total = group != nullptr ? set.total : m;
  check_particle_count(total);
  const std::size_t blocks = blocks_of(total);
  const std::size_t b0 = group != nullptr ? set.first / kBlock : 0;
  const std::size_t local_blocks = blocks_of(m);
  block_max_.resize(blocks);
  block_bad_.resize(blocks);
  block_bad_value_.resize(blocks);
  block_square_.resize(blocks);
  block_offset_.resize(blocks + 1);
  if (local_prefix_.size() < m) {
    local_prefix_.resize(m);
  }
  const double* l = log_weight.data();
  const ParticleKernel& kernel = *kernel_;
  const std::size_t g = grain();

  // Pass 1: the maximum, and the first NaN / +inf (as a particle of the whole set).
  kernel.for_each_fixed_block(
      m, kBlock,
      [&](std::size_t b, std::size_t begin, std::size_t end) {
        const BlockCheck check = check_block(l, begin, end);
        block_max_[b0 + b] = check.max;
        block_bad_[b0 + b] = check.bad == kNone ? kNone : set.first + check.bad;
        block_bad_value_[b0 + b] = check.bad == kNone ? 0.0 : l[check.bad];
      },
      g);
  if (group != nullptr) {
    struct Check {
      double max, bad_value;
      std::uint64_t bad;
    };
    std::vector<Check> mine(local_blocks);
    for (std::size_t b = 0; b < local_blocks; ++b) {
      mine[b] = {block_max_[b0 + b], block_bad_value_[b0 + b], block_bad_[b0 + b]};
    }
    const std::vector<Check> all = all_gather_values(*group, std::span<const Check>(mine));
    for (std::size_t b = 0; b < blocks; ++b) {
      block_max_[b] = all[b].max;
      block_bad_value_[b] = all[b].bad_value;
      block_bad_[b] = all[b].bad;
    }
  }
  BlockCheck all;
  double bad_value = 0.0;
  for (std::size_t b = 0; b < blocks; ++b) {
    if (all.bad == kNone && block_bad_[b] != kNone) bad_value = block_bad_value_[b];
    all = combine_checks(all, {block_max_[b], block_bad_[b]});
  }
  if (all.bad != kNone) throw_bad_weight(all.bad, bad_value);
  if (all.max == -kInf) throw_all_zero(total);
  const double max = all.max;

  // Pass 2: e_i, the local prefixes, block sums and sums of squares.
  double* prefix = local_prefix_.data();
  kernel.for_each_fixed_block(
      m, kBlock,
      [&](std::size_t b, std::size_t begin, std::size_t end) {
        const BlockSums sums = exp_prefix_block(l, max, prefix, begin, end);
        block_offset_[b0 + b + 1] = sums.sum;
        block_square_[b0 + b] = sums.square;
      },
      g);
  if (group != nullptr) {
    std::vector<BlockSums> mine(local_blocks);
    for (std::size_t b = 0; b < local_blocks; ++b) {
      mine[b] = {block_offset_[b0 + b + 1], block_square_[b0 + b]};
    }
    const std::vector<BlockSums> all_sums =
        all_gather_values(*group, std::span<const BlockSums>(mine));
    for (std::size_t b = 0; b < blocks; ++b) {
      block_offset_[b + 1] = all_sums[b].sum;
      block_square_[b] = all_sums[b].square;
    }
  }
  // The block offsets (sequential scan) and the sum of squares (left fold).
  block_offset_[0] = 0.0;
  double square = 0.0;
  for (std::size_t b = 0; b < blocks; ++b) {
    block_offset_[b + 1] = block_offset_[b] + block_offset_[b + 1];
    square += block_square_[b];
  }
  const double sum = block_offset_[blocks];  // >= 1: the largest e_i is exp(0)
  particles_ = m;
  total_ = total;
  first_block_ = b0;
  return {max, max + std::log(sum), sum * sum / square};
}

namespace {

// The first output k < n with t_k >= c, or n: the outputs before it are drawn from particles
// with C_i <= t_k. c == T (the last particles, and zero weights after them) takes every output
// left, as the merge's `top` does.
template <PointerModel Pointers>
std::uint64_t first_output_at_least(const Pointers& pointers, double c, double total,
                                    std::size_t n) noexcept {
  if (c == total) return n;
  const double guess = pointers.estimate(c, 0);
  std::size_t k = !(guess > 0.0)                    ? 0
                  : guess >= static_cast<double>(n) ? n
                                                    : static_cast<std::size_t>(guess);
  while (k > 0 && pointers.target_anywhere(k - 1) >= c) --k;
  while (k < n && pointers.target_anywhere(k) < c) ++k;
  return k;
}

}  // namespace

std::uint64_t Resampler::draw_ranges(ResampleScheme scheme, std::uint64_t seed,
                                     std::uint64_t step, std::span<std::uint64_t> ends) {
  if (particles_ == 0) {
    throw std::logic_error("Resampler::draw_ranges: no successful summarize before");
  }
  if (ends.size() != particles_) {
    throw std::invalid_argument("Resampler::draw_ranges: " + std::to_string(ends.size()) +
                                " ends for " + std::to_string(particles_) + " particles");
  }
  if (scheme == ResampleScheme::kMultinomial) {
    throw std::invalid_argument(
        "resample: multinomial resampling is not available over ranks (its pointers are a "
        "scan over every rank's spacings); use systematic or stratified");
  }
  const std::size_t n = total_;
  const double total = block_offset_[blocks_of(total_)];
  const double scale = total / static_cast<double>(n);
  const double inverse_scale = static_cast<double>(n) / total;
  const double* offset = block_offset_.data() + first_block_;
  const double* prefix = local_prefix_.data();
  auto run = [&](const auto& pointers) {
    // C_{first - 1} is the set's offset at this rank's first block: the same sum, so the same
    // bits, as the previous rank's last cumulative weight.
    const std::uint64_t start =
        first_block_ == 0 ? 0 : first_output_at_least(pointers, offset[0], total, n);
    kernel_->for_each_block(
        particles_,
        [&](std::size_t begin, std::size_t end) {
          for (std::size_t i = begin; i < end; ++i) {
            ends[i] = first_output_at_least(pointers, offset[i / kBlock] + prefix[i], total, n);
          }
        },
        grain());
    return start;
  };
  if (scheme == ResampleScheme::kSystematic) {
    RandomStream stream(StreamKey{seed, step, 0, Purpose::kResample});
    return run(SystematicPointers{stream.uniform(), scale, inverse_scale});
  }
  StratifiedPointers pointers;
  pointers.seed = seed;
  pointers.step = step;
  pointers.scale = scale;
  pointers.inverse_scale = inverse_scale;
  return run(pointers);
}

void Resampler::draw(ResampleScheme scheme, std::uint64_t seed, std::uint64_t step,
                     std::span<std::uint32_t> ancestors) {
  if (particles_ == 0) {
    throw std::logic_error("Resampler::draw: no successful summarize before");
  }
  if (total_ != particles_) {
    throw std::logic_error("Resampler::draw: the summary is of a shared set; use draw_ranges");
  }
  const std::size_t n = ancestors.size();
  check_draw_count(n);
  if (n == 0) {
    return;
  }
  const ParticleKernel& kernel = *kernel_;
  const std::size_t g = grain();
  const Cumulative c{local_prefix_.data(), block_offset_.data(), particles_};
  const double total = block_offset_[blocks_of(particles_)];
  const auto top = static_cast<std::uint32_t>(c.first_at_least(total));
  std::uint32_t* out = ancestors.data();

  const double scale = total / static_cast<double>(n);
  const double inverse_scale = static_cast<double>(n) / total;
  switch (scheme) {
    case ResampleScheme::kSystematic: {
      RandomStream stream(StreamKey{seed, step, 0, Purpose::kResample});
      const double u = stream.uniform();
      kernel.for_each_block(
          n,
          [&](std::size_t k0, std::size_t k1) {
            SystematicPointers pointers{u, scale, inverse_scale};
            merge_chunk(c, top, pointers, out, k0, k1);
          },
          g);
      break;
    }
    case ResampleScheme::kStratified: {
      kernel.for_each_block(
          n,
          [&](std::size_t k0, std::size_t k1) {
            StratifiedPointers pointers;
            pointers.seed = seed;
            pointers.step = step;
            pointers.scale = scale;
            pointers.inverse_scale = inverse_scale;
            merge_chunk(c, top, pointers, out, k0, k1);
          },
          g);
      break;
    }
    case ResampleScheme::kMultinomial: {
      // N + 1 exponential spacings, scanned with the same fixed blocks.
      const std::size_t spacings = n + 1;
      const std::size_t blocks = blocks_of(spacings);
      if (spacing_prefix_.size() < spacings) {
        spacing_prefix_.resize(spacings);
      }
      spacing_offset_.resize(blocks + 1);
      double* prefix = spacing_prefix_.data();
      kernel.for_each_fixed_block(
          spacings, kBlock,
          [&](std::size_t b, std::size_t begin, std::size_t end) {
            spacing_offset_[b + 1] = spacing_prefix_block(seed, step, prefix, begin, end);
          },
          g);
      spacing_offset_[0] = 0.0;
      for (std::size_t b = 0; b < blocks; ++b) {
        spacing_offset_[b + 1] = spacing_offset_[b] + spacing_offset_[b + 1];
      }
      const double spacing_total = spacing_offset_[blocks];
      const double spacing_scale = spacing_total > 0.0 ? total / spacing_total : 0.0;
      kernel.for_each_block(
          n,
          [&](std::size_t k0, std::size_t k1) {
            MultinomialPointers pointers{prefix, spacing_offset_.data(), spacing_scale};
            merge_chunk(c, top, pointers, out, k0, k1);
          },
          g);
      break;
    }
  }
}

ResampleOutcome Resampler::resample(memory::ParticleStore& store, std::uint64_t seed,
                                    std::uint64_t step, std::size_t gather_grain) {
  const std::span<double> log_weight = store.log_weight();
  const WeightSummary summary = summarize(log_weight);
  const std::size_t m = log_weight.size();
  const ParticleKernel& kernel = *kernel_;
  if (!should_resample(policy_, summary.effective_sample_size, m)) {
    subtract_in_place(log_weight, summary.log_sum, kernel, grain());
    ancestors_.clear();
    return {false, summary};
  }
  ancestors_.resize(m);
  draw(policy_.scheme, seed, step, ancestors_);
  const std::size_t g = gather_grain != 0 ? gather_grain : grain();
  kernel.execute([&] { store.gather(ancestors_, g); });
  fill_in_place(store.log_weight(), -std::log(static_cast<double>(m)), kernel, grain());
  return {true, summary};
}

ResampleOutcome Resampler::resample(memory::ParticleStore& store, std::uint64_t seed,
                                    std::uint64_t step, const SharedSet& set,
                                    const MoveParticles& move) {
  const std::span<double> log_weight = store.log_weight();
  const WeightSummary summary = summarize(log_weight, set);
  const std::size_t total = total_;
  const ParticleKernel& kernel = *kernel_;
  if (!should_resample(policy_, summary.effective_sample_size, total)) {
    subtract_in_place(log_weight, summary.log_sum, kernel, grain());
    ancestors_.clear();
    return {false, summary};
  }
  ends_.resize(log_weight.size());
  const std::uint64_t start = draw_ranges(policy_.scheme, seed, step, ends_);
  move(start, ends_);
  fill_in_place(store.log_weight(), -std::log(static_cast<double>(total)), kernel, grain());
  return {true, summary};
}

WeightSummary summarize_log_weights(std::span<const double> log_weight,
                                    const ParticleKernel& kernel) {
  Resampler resampler({}, kernel);
  return resampler.summarize(log_weight);
}

WeightSummary normalise_log_weights(std::span<double> log_weight, const ParticleKernel& kernel) {
  const WeightSummary summary = summarize_log_weights(log_weight, kernel);
  subtract_in_place(log_weight, summary.log_sum, kernel, 0);
  return summary;
}

void reset_log_weights(std::span<double> log_weight, const ParticleKernel& kernel) {
  if (log_weight.empty()) {
    return;
  }
  fill_in_place(log_weight, -std::log(static_cast<double>(log_weight.size())), kernel, 0);
}

void draw_ancestors(ResampleScheme scheme, std::span<const double> log_weight, std::uint64_t seed,
                    std::uint64_t step, std::span<std::uint32_t> ancestors,
                    const ParticleKernel& kernel) {
  Resampler resampler({}, kernel);
  resampler.summarize(log_weight);
  resampler.draw(scheme, seed, step, ancestors);
}

void draw_ancestors_sequential(ResampleScheme scheme, std::span<const double> log_weight,
                               std::uint64_t seed, std::uint64_t step,
                               std::span<std::uint32_t> ancestors) {
  const std::size_t m = log_weight.size();
  check_particle_count(m);
  const std::size_t n = ancestors.size();
  check_draw_count(n);
  // Validation and maximum, one pass.
  double max = -kInf;
  for (std::size_t i = 0; i < m; ++i) {
    const double v = log_weight[i];
    if (std::isnan(v) || v == kInf) {
      throw_bad_weight(i, v);
    }
    max = std::max(max, v);
  }
  if (max == -kInf) {
    throw_all_zero(m);
  }
  // The cumulative weights, blocked: C_i = offset of i's block + running sum within it.
  std::vector<double> cumulative(m);
  double offset = 0.0;
  for (std::size_t begin = 0; begin < m; begin += kBlock) {
    const std::size_t end = std::min(m, begin + kBlock);
    double local = 0.0;
    for (std::size_t i = begin; i < end; ++i) {
      local += internal::exp_nonpositive(log_weight[i] - max);
      cumulative[i] = offset + local;
    }
    offset = offset + local;
  }
  const double total = offset;
  if (n == 0) {
    return;
  }
  // The pointers, as targets on the scale of the cumulative weights.
  std::vector<double> target(n);
  switch (scheme) {
    case ResampleScheme::kSystematic: {
      RandomStream stream(StreamKey{seed, step, 0, Purpose::kResample});
      const double u = stream.uniform();
      const double scale = total / static_cast<double>(n);
      for (std::size_t k = 0; k < n; ++k) {
        target[k] = (static_cast<double>(k) + u) * scale;
      }
      break;
    }
    case ResampleScheme::kStratified: {
      const double scale = total / static_cast<double>(n);
      for (std::size_t k = 0; k < n; ++k) {
        RandomStream stream(
            StreamKey{seed, step, static_cast<std::uint32_t>(k), Purpose::kResample});
        target[k] = (static_cast<double>(k) + stream.uniform()) * scale;
      }
      break;
    }
    case ResampleScheme::kMultinomial: {
      std::vector<double> spacing(n + 1);
      double spacing_offset = 0.0;
      for (std::size_t begin = 0; begin <= n; begin += kBlock) {
        const std::size_t end = std::min(n + 1, begin + kBlock);
        double local = 0.0;
        for (std::size_t j = begin; j < end; ++j) {
          RandomStream stream(
              StreamKey{seed, step, static_cast<std::uint32_t>(j), Purpose::kResample});
          local += -std::log1p(-stream.uniform());
          spacing[j] = spacing_offset + local;
        }
        spacing_offset = spacing_offset + local;
      }
      const double scale = spacing_offset > 0.0 ? total / spacing_offset : 0.0;
      for (std::size_t k = 0; k < n; ++k) {
        target[k] = spacing[k] * scale;
      }
      break;
    }
  }
  // The textbook merge.
  std::size_t top = 0;
  while (cumulative[top] < total) {
    ++top;
  }
  std::size_t i = 0;
  for (std::size_t k = 0; k < n; ++k) {
    if (target[k] >= total) {
      ancestors[k] = static_cast<std::uint32_t>(top);
      continue;
    }
    while (cumulative[i] <= target[k]) {
      ++i;
    }
    ancestors[k] = static_cast<std::uint32_t>(i);
  }
}

WeightedPose weighted_mean_pose(const memory::ParticleStore& store, const ParticleKernel& kernel) {
  const std::span<const double> l = store.log_weight();
  check_particle_count(l.size());
  const BlockCheck check = kernel.reduce(
      l.size(), BlockCheck{},
      [&](std::size_t begin, std::size_t end) { return check_block(l.data(), begin, end); },
      combine_checks);
  const double max = checked_max(check, l);
  const std::span<const double> x = store.x(), y = store.y(), theta = store.theta();
  const PoseSums sums = kernel.reduce(
      l.size(), PoseSums{},
      [&](std::size_t begin, std::size_t end) {
        return pose_block(l.data(), max, x.data(), y.data(), theta.data(), begin, end);
      },
      [](const PoseSums& a, const PoseSums& b) {
        return PoseSums{a.w + b.w, a.x + b.x, a.y + b.y, a.c + b.c, a.s + b.s};
      });
  return {sums.x / sums.w, sums.y / sums.w, std::atan2(sums.s, sums.c)};
}

std::size_t best_particle(std::span<const double> log_weight, const ParticleKernel& kernel) {
  check_particle_count(log_weight.size());
  struct Best {
    double value = -kInf;
    std::size_t index = kNone;
    std::size_t bad = kNone;
  };
  const Best best = kernel.reduce(
      log_weight.size(), Best{},
      [&](std::size_t begin, std::size_t end) {
        Best block;
        for (std::size_t i = begin; i < end; ++i) {
          const double v = log_weight[i];
          if (!(v < kInf)) {
            if (block.bad == kNone) {
              block.bad = i;
            }
          } else if (v > block.value) {
            block.value = v;
            block.index = i;
          }
        }
        return block;
      },
      [](const Best& a, const Best& b) {
        Best r = b.value > a.value ? b : a;
        r.bad = a.bad != kNone ? a.bad : b.bad;
        return r;
      });
  if (best.bad != kNone) {
    throw_bad_weight(best.bad, log_weight[best.bad]);
  }
  if (best.index == kNone) {
    throw_all_zero(log_weight.size());
  }
  return best.index;
}

}  // namespace fastslam::parallel
