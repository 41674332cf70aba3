// The rows of the structured numpy arrays the module returns (map, associations, trajectory,
// particles, log events, observations, true landmarks), laid out without padding so numpy
// shows plain dtypes, and their registration with pybind11 (once, at module import).
//
// Thread safety: plain values; `register_record_dtypes` needs the GIL. Costs: none at run time.
#pragma once

#include <cstdint>

namespace fastslam::bindings::python {

// engine::MapLandmark without its storage slot.
struct MapRecord {
  std::uint64_t id;
  double x, y, sxx, sxy, syy, log_odds;
  std::int64_t last_seen;
};

// engine::ObservationAssociation; `outcome` is engine::AssociationOutcome's value
// (fastslam.Outcome).
struct AssociationRecord {
  std::uint32_t observation;
  std::uint32_t outcome;
  std::uint64_t landmark_id;
  double mahalanobis2;
};

// engine::TrajectoryPoint.
struct TrajectoryRecord {
  std::uint64_t control;
  double x, y, theta;
};

// One particle of the filter: its pose, log-weight and landmark count.
struct ParticleRecord {
  double x, y, theta, log_weight;
  std::uint64_t landmarks;
};

// tools::Event; `kind` is tools::EventKind's value (fastslam.EventKind); a scan's observations
// are the log's observations[first:first + count].
struct EventRecord {
  double time;
  std::uint32_t kind;
  std::uint32_t count;
  std::uint64_t first;
  double dt, u0, u1, x, y, theta;
};

// engine::Observation (id -1: none).
struct ObservationRecord {
  double range, bearing;
  std::int64_t id;
};

// tools::TruthLandmark.
struct TruthRecord {
  std::uint64_t id;
  double x, y;
};

void register_record_dtypes();

}  // namespace fastslam::bindings::python
