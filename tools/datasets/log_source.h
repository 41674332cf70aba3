// A source over a log held in memory: readers that convert a data set whole (Victoria Park,
// UTIAS) use it for their events. (`--source log` streams its file: streamed_log_source.h.)
//
// Ownership: owns the log. Thread safety: thread-compatible. Costs: `next` copies a scan's
// observations; the log is held whole (tools/io/log_format.h).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "tools/datasets/source.h"
#include "tools/io/log_format.h"

namespace fastslam::tools {

class LogSource final : public Source {
 public:
  // `name` is the info's name (the file or directory read); `summary` the line convert prints;
  // `metrics` go to metrics.json as they are. A log read without its end marker
  // (Log::unterminated) is run with a warning (Source::warnings).
  LogSource(Log log, std::string name, std::string summary = {},
            std::vector<std::pair<std::string, double>> metrics = {});
  bool next(Event& event, std::vector<engine::Observation>& scan) override;
  // "FILE:LINE" when the log was read from a file.
  std::string where(std::uint64_t index) const override;
  // The reader's scoring recommendation (SourceInfo::match_radius, rpe_delta).
  void recommend_scoring(double match_radius, double rpe_delta) {
    info_.match_radius = match_radius;
    info_.rpe_delta = rpe_delta;
  }

 private:
  Log log_;
  std::size_t i_ = 0;
};

}  // namespace fastslam::tools
