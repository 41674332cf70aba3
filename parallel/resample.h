// Resampling and weight statistics: log-sum-exp normalisation, the effective sample size, the
// policy that decides when to resample, and systematic, stratified and multinomial draws.
//
// Design note. FastSLAM resamples every step (ALGORITHM.md, step 4; the paper, eq. 28); many
// users resample only when N_eff = 1 / sum w_i^2 drops below a fraction of M. Weights are kept
// as log-weights l_i and normalised with log-sum-exp: with m = max l_i, e_i = exp(l_i - m)
// (so the largest is 1 and nothing underflows as a whole), S = sum e_i, w_i = e_i / S,
// log-sum = m + log S, N_eff = S^2 / sum e_i^2.
//
// All three schemes share one code path: they produce N sorted pointers p_k in [0, 1) and one
// merge of the pointers against the cumulative weights picks, for each k, the first particle
// whose cumulative weight exceeds p_k:
//   systematic   p_k = (u + k) / N,   one u ~ U[0, 1) from the stream (seed, step, particle 0,
//                Purpose::kResample).
//   stratified   p_k = (u_k + k) / N, u_k the first uniform of stream (seed, step, k, kResample).
//   multinomial  p_k = G_k / G_N with G_k = E_0 + ... + E_k and E_j = -log(1 - u_j) ~ Exp(1)
//                (u_j from stream (seed, step, j, kResample), j = 0..N): the sorted order
//                statistics of N uniforms, generated in O(N) without sorting.
// The merge runs in parallel by chunks of outputs. A chunk finds its first particle by one
// binary search, then visits the particles whose answers fall in it; for each it finds the first
// pointer at or above its cumulative weight (in closed form for systematic and stratified, up
// to an exact correction; by walking the pointers for multinomial) and counts, and a running
// sum of the counts gives the chunk's indices. No data-dependent branch per output for
// systematic, which halves the cost of the textbook walk. Every index is a pure function of the
// cumulative weights and the pointers, so any chunking gives the textbook merge's result.
//
// Determinism (the crux). The cumulative weights C_i are defined by a fixed-shape scan: the
// particles are cut into blocks of K = ParticleKernel::kReduceBlock; within block b the local
// prefix L_i runs from 0 left to right; block offsets are O_0 = 0, O_{b+1} = O_b + L_last(b)
// (sequentially); and C_i = O_b + L_i. Every value is a fixed sequence of IEEE operations, so C
// is bit-identical for any thread count and grain, and equal to what the sequential reference
// `draw_ancestors_sequential` computes. The scan is also monotone (C_{i+1} >= C_i) and a particle
// of weight zero has C_i == C_{i-1} exactly, so it is never drawn. The exponential spacings of
// the multinomial scheme use the same scan. Sums of squares and the weighted mean pose use the
// same blocks, folded left to right.
// Selection rule: particle(k) = the first i with C_i > p_k * T (T = C_{M-1}, the total), or,
// when rounding makes p_k * T >= T, the first i with C_i == T (the last particle of positive
// weight, which is what exact arithmetic would pick). Indices come out sorted ascending.
//
// Degenerate input (documented choice):
//   - no particles: std::invalid_argument.
//   - NaN or +inf log-weight anywhere: std::invalid_argument naming the first such particle.
//     A NaN is a bug upstream; +inf is not a weight (it would make every other weight 0/inf).
//   - every log-weight -inf (all weights zero): std::domain_error. We do not silently reset to
//     uniform: a filter in which every particle has zero likelihood has met an observation its
//     models call impossible (an outlier, a wrong noise setting, a gating bug); resampling
//     uniformly would hide that and keep going on a meaningless posterior. The error is raised
//     before anything changes, so the caller (the engine) can choose to skip the observation,
//     reset the weights itself (`reset_log_weights`), or stop.
//   - one particle: fine (N_eff = 1, every draw picks it).
//   - more than 2^32 - 1 particles (indices are 32-bit): std::length_error.
// Individual weights may underflow: e_i is computed by internal::exp_nonpositive (our own exp,
// within 2 ulp, the same bits on every machine and C library), which gives exactly 0 below
// e^-708 relative to the largest weight; such particles are never drawn.
//
// Ownership: a `Resampler` borrows its `ParticleKernel` (which must outlive it) and owns its
// scratch buffers (reused across calls; they grow to the largest M seen). The free functions
// borrow their spans for the call only.
// Under ThreadSanitizer builds the kernel's `execute` has one slot (particle_kernel.h), so the
// gather inside `resample` then runs on the calling thread.
// Thread safety: a `Resampler` is thread-compatible (one call at a time per object; the calls
// run in parallel internally on the kernel's threads). The free functions are thread-safe.
// Costs (M particles, N draws): summary O(M) with one exp per particle; a draw O(M + N), plus
// O(N) uniforms (and logs) for stratified/multinomial; `resample` adds
// ParticleStore::gather (O(M) plus freeing the maps that die). Allocation: the Resampler's
// buffers on first use at a given size; the free functions allocate O(M) each call.
// Measured (BM_SystematicResample, summary + systematic draw, 2-core EPYC VM, -O3 -march=native,
// grain 512): about 6 ns per particle on one thread for M = 10^4 .. 10^6 (0.66 us at M = 100);
// two threads 1.05x at M = 10^3, 1.75x at 10^4, 1.94x at 10^5, 2.0x at 10^6; M <= grain runs
// inline (1.0x).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <oneapi/tbb/cache_aligned_allocator.h>

#include "memory/particle_store.h"
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
  // they never drift. `grain` (0: grain()) overrides the grain for this call: a filter whose
  // step was heavy has many path copies to release and splits its gather finely. Throws as
  // `summarize` (and then changes nothing), or std::bad_alloc.
  ResampleOutcome resample(memory::ParticleStore& store, std::uint64_t seed, std::uint64_t step,
                           std::size_t grain = 0);

  // Validates `log_weight` and returns its summary; keeps the cumulative weights for `draw`.
  // Throws std::invalid_argument (empty, or NaN / +inf at a named particle), std::domain_error
  // (every weight zero) or std::length_error (more than 2^32 - 1 particles).
  WeightSummary summarize(std::span<const double> log_weight);

  // Fills `ancestors` (N = ancestors.size() draws; N may differ from M, and 0 draws nothing)
  // with the indices drawn by `scheme` from the weights of the last `summarize`. Sorted
  // ascending. Throws std::logic_error when there was no summarize or the last one threw, and
  // std::length_error when N > 2^32 - 1.
  void draw(ResampleScheme scheme, std::uint64_t seed, std::uint64_t step,
            std::span<std::uint32_t> ancestors);

  // C_i, the blocked cumulative weight of particle i (unnormalised: C_{M-1} = sum exp(l_i - m)),
  // from the last successful `summarize`; for tests and diagnostics. O(1).
  // REQUIRES: i < M of that summarize.
  double cumulative_weight(std::size_t i) const noexcept {
    return block_offset_[i / ParticleKernel::kReduceBlock] + local_prefix_[i];
  }

  // The indices of the last draw of `resample` (empty when it did not resample).
  std::span<const std::uint32_t> last_ancestors() const noexcept { return ancestors_; }

 private:
  using Buffer = std::vector<double, tbb::cache_aligned_allocator<double>>;

  ResamplePolicy policy_;
  const ParticleKernel* kernel_;
  std::size_t grain_;                   // 0: the kernel's
  std::size_t particles_ = 0;           // M of the last successful summarize (0: none)
  Buffer local_prefix_;                 // L_i
  Buffer block_offset_;                 // O_b, b = 0..B (O_B = T)
  Buffer block_square_;                 // per block sum of e_i^2
  Buffer block_max_;                    // per block max l_i
  std::vector<std::size_t> block_bad_;  // per block first NaN / +inf particle (or none)
  Buffer spacing_prefix_;               // multinomial: local prefix of the exponential spacings
  Buffer spacing_offset_;               // multinomial: block offsets of the spacings
  std::vector<std::uint32_t> ancestors_;
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
