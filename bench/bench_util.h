// Helpers shared by the benchmarks: the smoke switch that tools/test.sh uses to run every
// benchmark once at tiny sizes (FASTSLAM_BENCH_SMOKE=1), so benchmarks never rot.
// Thread safety: functions read the environment only; call them during registration.
#pragma once

#include <cstdint>
#include <cstdlib>

namespace fastslam::bench {

// True when the benchmarks run as a smoke test (tiny sizes, one iteration each).
inline bool smoke() {
  const char* flag = std::getenv("FASTSLAM_BENCH_SMOKE");
  return flag != nullptr && flag[0] != '\0' && flag[0] != '0';
}

// `full` for a real run, `tiny` under the smoke switch: the upper end of a size sweep.
inline std::int64_t upto(std::int64_t full, std::int64_t tiny) { return smoke() ? tiny : full; }

}  // namespace fastslam::bench
