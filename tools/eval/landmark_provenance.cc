#include "tools/eval/landmark_provenance.h"

#include <algorithm>
#include <stdexcept>
#include <string>
#include <unordered_map>

namespace fastslam::tools {

void ObservationLabels::add(std::uint64_t step, std::span<const std::int32_t> labels) {
  if (!steps_.empty() && step <= steps_.back()) {
    throw std::invalid_argument("observation labels: scan step " + std::to_string(step) +
                                " is not after the last recorded one (" +
                                std::to_string(steps_.back()) + ")");
  }
  for (const std::int32_t l : labels) {
    if (l < kNoLandmark) {
      throw std::invalid_argument("observation labels: label " + std::to_string(l) +
                                  " is neither a landmark index nor kNoLandmark");
    }
  }
  if (offsets_.empty()) offsets_.push_back(0);
  steps_.push_back(step);
  labels_.insert(labels_.end(), labels.begin(), labels.end());
  offsets_.push_back(labels_.size());
}

std::optional<std::int32_t> ObservationLabels::label(std::uint64_t id) const {
  const std::uint64_t step = id / engine::kLandmarkIdsPerScan;
  const std::uint64_t j = id % engine::kLandmarkIdsPerScan;
  const auto at = std::lower_bound(steps_.begin(), steps_.end(), step);
  if (at == steps_.end() || *at != step) return std::nullopt;
  const std::size_t scan = static_cast<std::size_t>(at - steps_.begin());
  if (j >= offsets_[scan + 1] - offsets_[scan]) return std::nullopt;
  return labels_[offsets_[scan] + j];
}

Provenance landmark_provenance(std::span<const engine::MapLandmark> map,
                               const ObservationLabels& labels) {
  Provenance p;
  std::unordered_map<std::int32_t, std::size_t> started;  // true landmark -> landmarks it started
  for (const engine::MapLandmark& lm : map) {
    const std::optional<std::int32_t> l = labels.label(lm.id);
    if (!l) {
      ++p.unlabelled;
    } else if (*l == ObservationLabels::kNoLandmark) {
      ++p.from_false_alarms;
    } else {
      ++p.from_true_landmarks;
      if (++started[*l] > 1) ++p.second_copies;
    }
  }
  p.true_landmarks_mapped = started.size();
  return p;
}

}  // namespace fastslam::tools
