#include "engine/internal/resample_stage.h"

#include <algorithm>
#include <chrono>
#include <limits>
#include <stdexcept>
#include <string>

namespace fastslam::engine::internal {

ResampleStage::ResampleStage(const FilterConfig& config, const parallel::ParticleKernel& kernel)
    : kernel_(kernel),
      // Resampling costs nanoseconds per particle: its own grain (the kernel's default), so
      // that small filters resample inline. The result does not depend on it.
      resampler_(config.resample, kernel, parallel::KernelConfig{}.grain) {}

void ResampleStage::run(FilterState& state, std::uint64_t scan_step, bool heavy) {
  using Clock = std::chrono::steady_clock;
  const Clock::time_point t0 = Clock::now();
  FilterCounters& counters = state.counters;
  try {
    // After a heavy pass the gather releases many path copies: split it as finely as the pass;
    // after a light one it stays at the resampler's grain.
    const std::size_t threads = kernel_.threads();
    const std::size_t grain =
        heavy && threads > 1 ? std::max<std::size_t>(1, state.store.size() / (4 * threads)) : 0;
    const parallel::ResampleOutcome outcome =
        resampler_.resample(state.store, state.config.seed, scan_step, grain);
    counters.resamples += outcome.resampled ? 1 : 0;
    counters.log_evidence += outcome.before.log_sum;
  } catch (const std::invalid_argument& e) {
    // Not std::invalid_argument, whose contract is "unchanged": the scan has been applied.
    throw std::runtime_error("Filter::observe: numerical failure in scan " +
                             std::to_string(counters.scans) + " (step " +
                             std::to_string(scan_step) + "): " + e.what());
  } catch (const std::domain_error&) {
    // The maps already hold the scan; start the weights afresh rather than stop.
    parallel::reset_log_weights(state.store.log_weight(), kernel_);
    ++counters.weight_resets;
    counters.log_evidence = -std::numeric_limits<double>::infinity();
  }
  counters.resample_seconds += std::chrono::duration<double>(Clock::now() - t0).count();
}

}  // namespace fastslam::engine::internal
