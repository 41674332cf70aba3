// The readers' shared oracle: a log that was read writes (tools/io/log_format.h write_log) and
// reads back equal and whole (its end marker read), so reader and writer agree on everything a
// reader accepts. A difference aborts, which libFuzzer reports as a crash. Costs: O(log size).
#pragma once

#include <cstdio>
#include <cstdlib>
#include <sstream>

#include "tools/io/log_format.h"

namespace fastslam::fuzz {

inline void check_round_trip(const tools::Log& log) {
  std::ostringstream out;
  tools::write_log(out, log);
  std::istringstream in(out.str());
  const tools::Log back = tools::read_log(in, "round trip");
  if (!(back == log) || back.unterminated) {
    std::fprintf(stderr, "a log read back differs from the one written:\n%s\n", out.str().c_str());
    std::abort();
  }
}

}  // namespace fastslam::fuzz
