// Saving and loading a filter's whole state (engine/filter.h save / load) in a versioned binary
// format of native byte order: magic, version, sizeof(FilterConfig), the config bytes (padding
// zeroed), counters, the landmark variance bound, the clock, the last scan's report, queued
// controls, recorded trajectory points, the known-id table, the FastSLAM 2.0 covariances, the
// particle columns, then the particles' maps as one graph of nodes (memory/tree_graph.h): a
// node shared by many maps is written once and read back shared, so a state costs the
// particle set's distinct nodes and loads into the same live-node count. Spatial indices are
// not written: each is rebuilt from the previous particle's by the landmarks where the two
// maps differ (an index's entries are its map's slots and means, and queries are exact, so
// the rebuilt index answers the same). Equal states save equal bytes.
// Loading trusts nothing: every field is checked against the invariants the engine relies on
// (counters that add up, steps already taken, finite numbers, positive definite landmark
// covariances, distinct known ids that match every map, a well-formed node graph) and refused
// with std::runtime_error naming the field. Work and memory are bounded by the input's size:
// vectors are read in bounded chunks, so a corrupt length fails once the stream runs out instead
// of allocating what it claims; the particles are allocated only after the covariances (25
// doubles per particle) were read; a node is made only after its record was read.
// Thread safety: thread-compatible. Costs: O(distinct nodes) to save and load, plus the
// indices' changes between neighbouring particles.
#pragma once

#include <iosfwd>
#include <vector>

#include "engine/filter.h"
#include "engine/internal/filter_state.h"

namespace fastslam::engine::internal {

// Everything of a saved state that precedes the particles, validated.
struct StateHeader {
  FilterConfig config;
  FilterCounters counters;  // the saved ones; the timings and the evidence start at zero
  double variance_bound = 0.0;
  double time = 0.0;
  bool timed = false;
  std::vector<ObservationAssociation> associations;
  std::vector<PendingControl> pending;
  std::vector<TrajectoryPoint> trajectory;
  KnownSlots known;
  std::vector<std::int64_t> known_ids;  // each slot's id; every map holds these slots
  std::vector<double> covariances;
};

// Throws std::runtime_error when the stream fails.
void save_state(const FilterState& state, const std::vector<TrajectoryPoint>& trajectory,
                std::ostream& out);

// Reads and validates the header; throws std::runtime_error on a stream that is not a state.
StateHeader read_header(std::istream& in);

// Moves the header's contents but the trajectory into `state` (built from header.config) and
// reads the particles and their maps. Throws std::runtime_error on a corrupt stream.
void read_particles(std::istream& in, StateHeader&& header, FilterState& state);

}  // namespace fastslam::engine::internal
