#include "parallel/internal/random_dispatch.h"

#include <array>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <string>
#include <string_view>

#include "parallel/internal/random_kernels.h"

// parallel/CMakeLists.txt says which copies random_kernels.cc was compiled into:
// FASTSLAM_RANDOM_KERNELS_X86_DISPATCH for baseline, avx2 and avx512, otherwise
// FASTSLAM_RANDOM_KERNELS_SINGLE=<name> for one.
#if !defined(FASTSLAM_RANDOM_KERNELS_X86_DISPATCH) && !defined(FASTSLAM_RANDOM_KERNELS_SINGLE)
#error "parallel/CMakeLists.txt must say which copies of the random kernels exist"
#endif

namespace fastslam::parallel::internal {

// The tables of the copies (random_kernels.cc); only this build's are defined.
namespace kernels_native {
const RandomKernels& kernels() noexcept;
}
namespace kernels_baseline {
const RandomKernels& kernels() noexcept;
}
namespace kernels_avx2 {
const RandomKernels& kernels() noexcept;
}
namespace kernels_avx512 {
const RandomKernels& kernels() noexcept;
}

#if defined(FASTSLAM_RANDOM_KERNELS_X86_DISPATCH)
namespace {

// Whether this CPU and its operating system (the AVX state saved on context switches) run code
// compiled with -march=x86-64-v3, resp. -march=x86-64-v4, as the avx2 and avx512 copies are.
// GCC names the levels; Clang (14 at least, the clang-tidy here) does not, so there the check
// lists the features of each level that its compiler knows.
bool cpu_runs_x86_64_v3() noexcept {
#if defined(__clang__)
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
         __builtin_cpu_supports("bmi") && __builtin_cpu_supports("bmi2");
#else
  return __builtin_cpu_supports("x86-64-v3") != 0;
#endif
}
bool cpu_runs_x86_64_v4() noexcept {
#if defined(__clang__)
  return cpu_runs_x86_64_v3() && __builtin_cpu_supports("avx512f") &&
         __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512cd") &&
         __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512vl");
#else
  return __builtin_cpu_supports("x86-64-v4") != 0;
#endif
}

}  // namespace

std::span<const RandomKernelVariant> random_kernel_variants() noexcept {
  static const std::array<RandomKernelVariant, 3> variants = [] {
    __builtin_cpu_init();  // in case the first call comes from a static constructor
    return std::array<RandomKernelVariant, 3>{{
        {&kernels_baseline::kernels(), true},
        {&kernels_avx2::kernels(), cpu_runs_x86_64_v3()},
        {&kernels_avx512::kernels(), cpu_runs_x86_64_v4()},
    }};
  }();
  return variants;
}
#else
#define FASTSLAM_DISPATCH_CONCAT_(a, b) a##b
#define FASTSLAM_DISPATCH_CONCAT(a, b) FASTSLAM_DISPATCH_CONCAT_(a, b)
std::span<const RandomKernelVariant> random_kernel_variants() noexcept {
  static const std::array<RandomKernelVariant, 1> variants{
      {{&FASTSLAM_DISPATCH_CONCAT(kernels_, FASTSLAM_RANDOM_KERNELS_SINGLE)::kernels(), true}}};
  return variants;
}
#endif

RandomKernelChoice choose_random_kernels(std::span<const RandomKernelVariant> variants,
                                         const char* requested) {
  const RandomKernels* best = nullptr;
  for (const RandomKernelVariant& v : variants) {
    if (v.supported) best = v.kernels;
  }
  const std::string_view name = requested == nullptr ? std::string_view() : requested;
  if (name.empty() || name == "auto") return {best, {}};
  for (const RandomKernelVariant& v : variants) {
    if (v.kernels->name != name) continue;
    if (v.supported) return {v.kernels, {}};
    return {best, "fastslam: FASTSLAM_ISA=" + std::string(name) +
                      ": this CPU cannot run those kernels; using " + std::string(best->name)};
  }
  std::string names;
  for (const RandomKernelVariant& v : variants) {
    names += names.empty() ? "" : ", ";
    names += v.kernels->name;
  }
  return {best, "fastslam: FASTSLAM_ISA=" + std::string(name) + " is not one of this build's " +
                    "random-stream kernels (" + names + "; or auto); using " +
                    std::string(best->name)};
}

const RandomKernels& random_kernels() noexcept {
  static const RandomKernels& chosen = []() -> const RandomKernels& {
    const RandomKernelChoice choice =
        choose_random_kernels(random_kernel_variants(), std::getenv("FASTSLAM_ISA"));
    if (!choice.warning.empty()) std::fprintf(stderr, "%s\n", choice.warning.c_str());
    return *choice.kernels;
  }();
  return chosen;
}

}  // namespace fastslam::parallel::internal
