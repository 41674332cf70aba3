// Where the landmarks of a map estimated under unknown association came from. The engine names
// each landmark it starts after the observation that started it (engine::MapLandmark::id), and a
// simulator (or a data set with labelled detections) knows what each observation saw: a true
// landmark, or nothing (a false alarm). So every reported landmark traces back to a true landmark
// or to a false alarm, and the map's errors split into what a distance cut-off cannot tell apart:
//   - from_false_alarms: landmarks a false alarm started (what clutter leaves in the map);
//   - second_copies: landmarks beyond the first that one true landmark started (twins);
//   - true_landmarks_mapped: distinct true landmarks that started a reported landmark.
// A real landmark mapped metres off (the map bent before a loop closed) is neither: GOSPA's
// distance and unassigned counts (map_metrics.h) report it. The labels are those of the
// starting observation: a false alarm's landmark that later took a true landmark's detections
// still counts as the false alarm's.
//
// Ownership: ObservationLabels owns one 4-byte label per recorded observation and 16 bytes per
// scan. Thread safety: thread-compatible. Costs: add is O(observations); label and
// landmark_provenance are O(log scans) per landmark.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "engine/filter.h"

namespace fastslam::tools {

class ObservationLabels {
 public:
  static constexpr std::int32_t kNoLandmark = -1;  // a false alarm, or a detection of no true one

  // Records the scan the filter processed at `step` (its step counter: controls and scans
  // before it): label i is the index of the true landmark observation i saw, or kNoLandmark.
  // Throws std::invalid_argument unless `step` exceeds every recorded one and each label is
  // kNoLandmark or >= 0.
  void add(std::uint64_t step, std::span<const std::int32_t> labels);

  // The label of the observation that started landmark `id`, or nothing when no recorded scan
  // holds it (an id of a prior map, or of a scan not recorded).
  std::optional<std::int32_t> label(std::uint64_t id) const;

  std::size_t scans() const noexcept { return steps_.size(); }

 private:
  std::vector<std::uint64_t> steps_;  // ascending
  std::vector<std::size_t> offsets_;  // first label of each scan; one past the end last
  std::vector<std::int32_t> labels_;
};

struct Provenance {
  std::size_t from_true_landmarks = 0;
  std::size_t from_false_alarms = 0;
  std::size_t second_copies = 0;  // among from_true_landmarks
  std::size_t true_landmarks_mapped = 0;
  std::size_t unlabelled = 0;  // ids no recorded observation started
};

Provenance landmark_provenance(std::span<const engine::MapLandmark> map,
                               const ObservationLabels& labels);

}  // namespace fastslam::tools
