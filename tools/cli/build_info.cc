#include "tools/cli/build_info.h"

#include <nlohmann/json.hpp>

#include "parallel/random_stream.h"
#include "tools/cli/build_info_values.h"

namespace fastslam::tools {
namespace {

// The widest x86 vector extension this file was compiled for: what "native" kernels use,
// since every target of a build gets the same -march.
constexpr const char* kCompiledSimd =
#if defined(__AVX512F__)
    "avx512";
#elif defined(__AVX2__)
    "avx2";
#elif defined(__SSE2__)
    "sse2";
#else
    "none";
#endif

// Whether `fastslam sweep` can spread its runs over MPI ranks (tools/cli/sweep_command.h).
constexpr const char* kMpi =
#ifdef FASTSLAM_HAVE_MPI
    "yes (fastslam sweep under mpirun spreads its runs over the ranks)";
#else
    "no (fastslam sweep runs on local threads only)";
#endif

}  // namespace

BuildInfo build_info() {
  return BuildInfo{.version = FASTSLAM_BUILD_VERSION,
                   .commit = FASTSLAM_BUILD_COMMIT,
                   .dirty = FASTSLAM_BUILD_DIRTY,
                   .build_type = FASTSLAM_BUILD_TYPE,
                   .compiler = FASTSLAM_BUILD_COMPILER,
                   .simd = std::string(parallel::random_stream_isa()),
                   .compiled_simd = kCompiledSimd};
}

std::string version_text() {
  const BuildInfo b = build_info();
  return "fastslam " + b.version + "\ncommit " + b.commit +
         (b.dirty ? " (with uncommitted changes)" : "") + "\nbuild type " + b.build_type +
         "\ncompiler " + b.compiler + "\nsimd " + b.simd +
         " (random-stream kernels; FASTSLAM_ISA=baseline|avx2|avx512 forces one in a portable "
         "build), compiled for " +
         b.compiled_simd + "\nmpi " + kMpi;
}

nlohmann::json build_info_json() {
  const BuildInfo b = build_info();
  return {{"version", b.version},
          {"commit", b.commit},
          {"dirty", b.dirty},
          {"build_type", b.build_type},
          {"compiler", b.compiler},
          {"simd", b.simd},
          {"compiled_simd", b.compiled_simd}};
}

}  // namespace fastslam::tools
