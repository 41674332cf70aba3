// Saving and loading a filter's whole state (engine/filter.h save / load) in a versioned binary
// format of native byte order: magic, version, sizeof(FilterConfig), the config bytes (padding
// zeroed), counters, the landmark variance bound, the clock, the last scan's report, queued
// controls, recorded trajectory points, the known-id table, the FastSLAM 2.0 covariances, the
// particle columns, then per particle either "same map as particle i-1" or its landmarks (slot,
// value). Spatial indices are not
// written: they are rebuilt from the maps (an index's entries are its map's slots and means, and
// queries are exact, so the rebuilt index answers the same). Equal states save equal bytes.
// Loading trusts nothing: every length is checked against what the configuration implies and
// vectors are read in bounded chunks, so a corrupt length fails with std::runtime_error once the
// stream runs out instead of allocating what it claims; the particles are allocated only after
// the covariances (25 doubles per particle) were read.
// Thread safety: thread-compatible. Costs: O(M N) worst case (maps that share a root are written
// once); load allocates as the stream delivers.
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
  std::size_t known_entries = 0;  // the table's saved length (each map holds that many)
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
