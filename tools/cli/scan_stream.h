// `--stream FILE|-`: one JSON object per line for every scan, written and flushed as the scan is
// processed, so a front end reading a pipe sees each estimate as it is made. A line holds the
// scan's time and index, the weighted mean pose (x, y, theta) and its 3x3 covariance
// (row-major), the effective sample size, the best particle's landmark count, each
// observation's association in the most likely particle, and the latency from reading the
// record to the estimate (ms). docs/streaming.md has the keys; a distance that is +inf (no
// candidate) is null.
//
// Ownership: owns its file; borrows standard output for "-". Thread safety: thread-compatible.
// Costs: O(Z) per line, one flush.
#pragma once

#include <cstdint>
#include <cstdio>
#include <string>

#include "engine/filter.h"

namespace fastslam::tools {

class ScanStream {
 public:
  // Throws std::runtime_error "--stream PATH: cannot open for writing".
  explicit ScanStream(const std::string& path);
  ~ScanStream();
  ScanStream(const ScanStream&) = delete;
  ScanStream& operator=(const ScanStream&) = delete;

  // Writes and flushes the line of scan `scan` (from 0). Throws std::runtime_error when the
  // write fails (a closed pipe).
  void write(double time, std::uint64_t scan, const engine::Estimate& estimate,
             double latency_seconds);

 private:
  std::string path_;
  std::FILE* file_ = nullptr;
  bool owned_ = false;
  std::string line_;
};

}  // namespace fastslam::tools
