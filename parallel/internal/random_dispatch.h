// Which copy of the random-stream batch kernels (random_kernels.h) a process runs (not API).
// A portable build has baseline, avx2 and avx512 copies and uses the most capable one this
// CPU runs; the environment variable FASTSLAM_ISA=baseline|avx2|avx512 forces a copy, so that
// tests can run each on one machine (all give the same bits). A request the build or the CPU
// cannot honour falls back to the most capable copy with a warning on stderr, rather than
// stopping a consumer's process. Other builds have one copy, native, and ignore FASTSLAM_ISA
// (with the same warning when it names anything else).
// Thread safety: random_kernels() is thread-safe (chosen once, under a function-local static);
// the others are pure or read constants. Costs: the first random_kernels() call reads the CPU's
// features and the environment; later calls O(1). choose_random_kernels allocates only for a
// warning.
#pragma once

#include <span>
#include <string>

#include "parallel/internal/random_kernels.h"

namespace fastslam::parallel::internal {

// A copy of the kernels in this build, and whether this CPU can run it.
struct RandomKernelVariant {
  const RandomKernels* kernels = nullptr;
  bool supported = false;
};

// This build's copies, least capable first; the first is always supported.
std::span<const RandomKernelVariant> random_kernel_variants() noexcept;

struct RandomKernelChoice {
  const RandomKernels* kernels = nullptr;
  std::string warning;  // empty unless `requested` was set and could not be honoured
};

// The copy named by `requested` when it is among `variants` and supported; otherwise the last
// supported one, with a warning naming the request when it was neither null, empty nor "auto".
// REQUIRES: some entry of variants is supported.
RandomKernelChoice choose_random_kernels(std::span<const RandomKernelVariant> variants,
                                         const char* requested);

// The copy this process uses: choose_random_kernels(random_kernel_variants(),
// getenv("FASTSLAM_ISA")) at the first call, its warning printed to stderr once.
const RandomKernels& random_kernels() noexcept;

}  // namespace fastslam::parallel::internal
