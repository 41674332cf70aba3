// Resampling and weight statistics: log-sum-exp normalisation, the effective sample size, the
// policy deciding when to resample, and systematic, stratified and multinomial draws, all by
// one merge of sorted pointers against cumulative weights. The cumulative weights come from a
// fixed-shape scan (blocks of ParticleKernel::kReduceBlock), so every result is bit-identical
// for any thread count and grain and equal to draw_ancestors_sequential. Ancestor indices come
// out sorted. Degenerate input: no particles, a NaN or +inf log-weight: std::invalid_argument;
// every weight zero: std::domain_error, before anything changes; more than 2^32 - 1 particles:
// std::length_error. Design and the selection rule: docs/parallel.md.
// Ownership: a Resampler borrows its ParticleKernel (which must outlive it) and owns scratch
// buffers reused across calls; the free functions borrow their spans for the call.
// Thread safety: a Resampler is thread-compatible (calls run in parallel internally); the free
// functions are thread-safe.
// Costs (M particles, N draws): summary O(M), one exp each; a draw O(M + N) (plus O(N)
// uniforms for stratified and multinomial); resample adds ParticleStore::gather. The
// Resampler allocates only when M grows; the free functions allocate O(M) per call.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <span>
#include <vector>

#include <oneapi/tbb/cache_aligned_allocator.h>

#include "memory/particle_store.h"
#include "parallel/collective.h"
#include "parallel/particle_kernel.h"

namespace fastslam::parallel {

enum class ResampleScheme : std::uint8_t { kSystematic, kStratified, kMultinomial };

// When to resample, and how.
struct ResamplePolicy {
  enum class When : std::uint8_t {
    kEveryStep,         // the paper: resample after every weight update
    kEssBelowFraction,  // resample when N_eff < ess_fraction * M
  };
  When when = When::kEveryStep;
  double ess_fraction = 0.5;  // in [0, 1]; only with kEssBelowFraction
  ResampleScheme scheme = ResampleScheme::kSystematic;
};

// Throws std::invalid_argument when ess_fraction is not in [0, 1] (or NaN).
void validate(const ResamplePolicy& policy);
// True when `policy` asks to resample M particles whose effective sample size is `ess`.
bool should_resample(const ResamplePolicy& policy, double ess, std::size_t particles) noexcept;

// What the weights look like (of the log-weights as given, before any normalisation).
struct WeightSummary {
  double max_log_weight = 0.0;         // m = max l_i
  double log_sum = 0.0;                // log sum exp(l_i), by log-sum-exp
  double effective_sample_size = 0.0;  // N_eff = 1 / sum w_i^2, in [1, M]
};

// A particle set shared by a group of ranks (parallel/collective.h), for the distributed forms:
// this rank holds particles [first, first + its count) of `total`, as particle_share deals them.
// Without a group the set is the local particles alone.
struct SharedSet {
  Collective* group = nullptr;
  std::size_t first = 0;
  std::size_t total = 0;
};

// The result of `Resampler::resample`.
struct ResampleOutcome {
  bool resampled = false;
  WeightSummary before;  // the weights the decision was taken on
};

// Resampling with reusable buffers; the engine keeps one per filter.
class Resampler {
 public:
  // `grain`: particles per task of the resampling passes (0: the kernel's grain). The passes
  // cost a few ns per particle, so grains of a few thousand suit them even when the engine's
  // heavy phases use small ones; the grain never changes the results. Throws as
  // validate(policy).
  Resampler(ResamplePolicy policy, const ParticleKernel& kernel, std::size_t grain = 0);

  const ResamplePolicy& policy() const noexcept { return policy_; }
  const ParticleKernel& kernel() const noexcept { return *kernel_; }
  std::size_t grain() const noexcept { return grain_ != 0 ? grain_ : kernel_->grain(); }

  // The one call of a filter step: summarise store.log_weight(); if the policy says so, draw
  // M ancestors with the policy's scheme from the streams of (seed, step), gather the store
  // (in the kernel's arena; maps no survivor holds are released in parallel) and set every
  // log-weight to -log M; otherwise normalise the log-weights in place (l_i -= log-sum), so
  // they never drift. `gather_grain` (0: grain()) is the gather's: it costs tens of ns per
  // particle, and more when a heavy step left many path copies to release, where the scans
  // cost a few. Throws as `summarize` (and then changes nothing), or std::bad_alloc.
  ResampleOutcome resample(memory::ParticleStore& store, std::uint64_t seed, std::uint64_t step,
                           std::size_t gather_grain = 0);

  // `resample` over a shared set, of which `store` holds this rank's share (a collective call):
  // the summary and the decision are the set's; the draw is draw_ranges'; `move(start, ends)`
  // must then replace the store by this rank's share of the outputs (the engine's particle
  // exchange), after which every log-weight is -log(set.total). Throws as summarize and
  // draw_ranges (then changing nothing), and what `move` throws.
  using MoveParticles = std::function<void(std::uint64_t start, std::span<const std::uint64_t>)>;
  ResampleOutcome resample(memory::ParticleStore& store, std::uint64_t seed, std::uint64_t step,
                           const SharedSet& set, const MoveParticles& move);

  // Validates `log_weight` and returns its summary; keeps the cumulative weights for `draw`.
  // Throws std::invalid_argument (empty, or NaN / +inf at a named particle), std::domain_error
  // (every weight zero) or std::length_error (more than 2^32 - 1 particles).
  WeightSummary summarize(std::span<const double> log_weight);
  // The same over a shared set, of which `log_weight` is this rank's share: a collective call
  // (two all_gathers of a few doubles per block); every rank gets the summary, and throws the
  // same error, one process would over all particles (the errors name global particles).
  WeightSummary summarize(std::span<const double> log_weight, const SharedSet& set);

  // Fills `ancestors` (N = ancestors.size() draws; N may differ from M, and 0 draws nothing)
  // with the indices drawn by `scheme` from the weights of the last `summarize`. Sorted
  // ascending. Throws std::logic_error when there was no summarize or the last one threw, and
  // std::length_error when N > 2^32 - 1.
  void draw(ResampleScheme scheme, std::uint64_t seed, std::uint64_t step,
            std::span<std::uint32_t> ancestors);

  // The draw of `scheme` with as many outputs as the set has particles, from this rank's side:
  // ends[i] (for each local particle i, ends.size() == its count) is one past the last output
  // drawn from it, so its copies are the outputs [ends[i - 1], ends[i]), with ends[-1] the
  // returned start; outputs are global indices, as `draw` would number them, and the ranges
  // count `draw`'s ancestors exactly (same pointers, same cumulative weights). O(M / R) with
  // no communication. Throws std::invalid_argument for kMultinomial, whose pointers need every
  // rank's spacings, or a wrong `ends` size; std::logic_error as draw.
  std::uint64_t draw_ranges(ResampleScheme scheme, std::uint64_t seed, std::uint64_t step,
                            std::span<std::uint64_t> ends);

  // C_i, the blocked cumulative weight of particle i (unnormalised: C_{M-1} = sum exp(l_i - m)),
  // from the last successful `summarize`; for tests and diagnostics. O(1).
  // REQUIRES: i < M of that summarize.
  double cumulative_weight(std::size_t i) const noexcept {
    return block_offset_[first_block_ + i / ParticleKernel::kReduceBlock] + local_prefix_[i];
  }

  // The indices of the last draw of `resample` (empty when it did not resample).
  std::span<const std::uint32_t> last_ancestors() const noexcept { return ancestors_; }

 private:
  using Buffer = std::vector<double, tbb::cache_aligned_allocator<double>>;

  ResamplePolicy policy_;
  const ParticleKernel* kernel_;
  std::size_t grain_;                   // 0: the kernel's
  std::size_t particles_ = 0;           // M of the last successful summarize (0: none)
  std::size_t total_ = 0;               // the set's M (= particles_ without a group)
  std::size_t first_block_ = 0;         // the set's block of local particle 0
  Buffer local_prefix_;                 // L_i
  Buffer block_offset_;                 // O_b, b = 0..B (O_B = T), over the whole set
  Buffer block_square_;                 // per block sum of e_i^2
  Buffer block_max_;                    // per block max l_i
  std::vector<std::size_t> block_bad_;  // per block first NaN / +inf particle (or none)
  Buffer block_bad_value_;              // its log-weight
  Buffer spacing_prefix_;               // multinomial: local prefix of the exponential spacings
  Buffer spacing_offset_;               // multinomial: block offsets of the spacings
  std::vector<std::uint32_t> ancestors_;
  std::vector<std::uint64_t> ends_;
};

// Convenience forms that allocate their buffers per call.
WeightSummary summarize_log_weights(std::span<const double> log_weight,
                                    const ParticleKernel& kernel);
// l_i -= log-sum, in place (afterwards sum exp(l_i) == 1 up to rounding); returns the summary of
// the input. Throws as summarize_log_weights, and then leaves the weights unchanged.
WeightSummary normalise_log_weights(std::span<double> log_weight, const ParticleKernel& kernel);
// Every log-weight set to -log M (uniform, normalised). A no-op for an empty span.
void reset_log_weights(std::span<double> log_weight, const ParticleKernel& kernel);
void draw_ancestors(ResampleScheme scheme, std::span<const double> log_weight, std::uint64_t seed,
                    std::uint64_t step, std::span<std::uint32_t> ancestors,
                    const ParticleKernel& kernel);

// The sequential reference: one thread, plain loops, the textbook merge (i advances while
// C_i <= p_k * T) over the same blocked cumulative sums. Returns the same indices as
// draw_ancestors bit for bit, and throws the same errors.
void draw_ancestors_sequential(ResampleScheme scheme, std::span<const double> log_weight,
                               std::uint64_t seed, std::uint64_t step,
                               std::span<std::uint32_t> ancestors);

// The weighted mean pose: x, y averaged with the normalised weights, theta as the direction of
// the weighted mean of (cos theta, sin theta) (the circular mean, in (-pi, pi]; 0 when the
// weighted unit vectors cancel exactly). Deterministic (fixed blocks, left fold) for any thread
// count and grain. Throws as summarize_log_weights on the store's log-weights.
struct WeightedPose {
  double x = 0.0;
  double y = 0.0;
  double theta = 0.0;
};
WeightedPose weighted_mean_pose(const memory::ParticleStore& store, const ParticleKernel& kernel);

// The particle of largest log-weight (the lowest index among ties). Throws as
// summarize_log_weights.
std::size_t best_particle(std::span<const double> log_weight, const ParticleKernel& kernel);

}  // namespace fastslam::parallel
