#include "tools/datasets/log_source.h"

#include <memory>
#include <stdexcept>
#include <utility>

namespace fastslam::tools {

LogSource::LogSource(Log log, std::string name, std::string summary,
                     std::vector<std::pair<std::string, double>> metrics)
    : log_(std::move(log)) {
  info_.header = log_.header;
  info_.landmarks = log_.landmarks;
  ScanShapeCounter shape;
  for (const Event& e : log_.events) {
    info_.expected_controls += e.kind == EventKind::kControl;
    shape.add(e);
  }
  info_.scans = shape.shape(true);
  std::size_t labelled = 0;
  for (const engine::Observation& z : log_.observations) labelled += z.id >= 0;
  info_.labels = labels_of(labelled, log_.observations.size());
  info_.name = std::move(name);
  info_.summary = std::move(summary);
  info_.metrics = std::move(metrics);
  if (log_.unterminated) warnings_.push_back(unterminated_log_warning(info_.name));
}

bool LogSource::next(Event& e, std::vector<engine::Observation>& scan) {
  if (i_ == log_.events.size()) return false;
  e = log_.events[i_++];
  if (e.kind == EventKind::kScan) {
    const auto first = log_.observations.begin() + static_cast<std::ptrdiff_t>(e.first);
    scan.assign(first, first + e.count);
  }
  return true;
}

std::string LogSource::where(std::uint64_t index) const {
  if (index < log_.lines.size()) return info_.name + ":" + std::to_string(log_.lines[index]);
  return Source::where(index);
}

}  // namespace fastslam::tools
