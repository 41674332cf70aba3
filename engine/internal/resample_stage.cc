#include "engine/internal/resample_stage.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "engine/internal/particle_exchange.h"

namespace fastslam::engine::internal {

ResampleStage::ResampleStage(const FilterConfig& config, const parallel::ParticleKernel& kernel)
    : kernel_(kernel),
      // The resampler's scans (weights, draw) cost a few ns per particle, less than a task's
      // hand-off below a few thousand particles: they run inline up to kScanGrain. The result
      // does not depend on the grain.
      resampler_(config.resample, kernel, kScanGrain) {}

void ResampleStage::run(FilterState& state, std::uint64_t scan_step, bool heavy) {
  using Clock = std::chrono::steady_clock;
  const Clock::time_point t0 = Clock::now();
  FilterCounters& counters = state.counters;
  try {
    // The gather costs tens of ns per particle: the kernel's default grain; after a heavy pass
    // it releases many path copies, split as finely as the pass.
    const std::size_t threads = kernel_.threads();
    const std::size_t grain = heavy && threads > 1
                                  ? std::max<std::size_t>(1, state.store.size() / (4 * threads))
                                  : parallel::KernelConfig{}.grain;
    parallel::ResampleOutcome outcome;
    if (state.group == nullptr) {
      outcome = resampler_.resample(state.store, state.config.seed, scan_step, grain);
    } else {
      // A shared set: the set's draw, then the particles bound for other ranks move.
      const parallel::SharedSet set{state.group, state.first_particle, state.config.particles};
      outcome = resampler_.resample(
          state.store, state.config.seed, scan_step, set,
          [&](std::uint64_t start, std::span<const std::uint64_t> ends) {
            const Clock::time_point e0 = Clock::now();
            const ExchangeCounts moved =
                exchange_particles(state, kernel_, start, ends, std::max<std::size_t>(grain, 256));
            ExchangeTotals& x = state.exchange;
            x.particles += moved.particles_sent;
            x.copies += moved.copies_sent;
            x.bytes += moved.bytes_sent;
            x.naive_bytes += moved.naive_bytes;
            x.seconds += std::chrono::duration<double>(Clock::now() - e0).count();
          });
    }
    counters.resamples += outcome.resampled ? 1 : 0;
    counters.log_evidence += outcome.before.log_sum;
  } catch (const std::invalid_argument& e) {
    // Not std::invalid_argument, whose contract is "unchanged": the scan has been applied.
    throw std::runtime_error("Filter::observe: numerical failure in scan " +
                             std::to_string(counters.scans) + " (step " +
                             std::to_string(scan_step) + "): " + e.what());
  } catch (const std::domain_error&) {
    // The maps already hold the scan; start the weights afresh rather than stop (every rank
    // of a shared set takes this branch: the summary is the set's).
    const std::span<double> lw = state.store.log_weight();
    std::fill(lw.begin(), lw.end(), -std::log(static_cast<double>(state.config.particles)));
    ++counters.weight_resets;
    counters.log_evidence = -std::numeric_limits<double>::infinity();
  }
  counters.resample_seconds += std::chrono::duration<double>(Clock::now() - t0).count();
}

}  // namespace fastslam::engine::internal
