// Resampling over ranks (a particle set shared by a group, parallel/collective.h): after the
// set's draw (parallel::Resampler::draw_ranges) each rank knows which outputs copy each of its
// particles; `exchange_particles` sends the copies bound for other ranks' slots and replaces the
// store by this rank's share of the outputs, in output order, so the set afterwards is the one
// one process's gather makes, dealt as particle_share deals it.
// A message carries the names this rank retired that the receiver holds (below), then per
// particle sent its copy count, its pose and velocities, its FastSLAM 2.0 covariance when
// carried, then the particles' maps as one node graph in the linked form (memory/tree_graph.h):
// a subtree the receiver holds already is sent as its name, any other once per message.
// Names (memory/node_registry.h, FilterState::links): a node gets one when it is first sent, or
// when a prior map is set (pinned: every rank builds it alike); each rank lists, per other rank,
// the names it sent to it or received from it. After the exchange each rank sweeps its registry:
// the named nodes no particle holds retire (resolvable until the next exchange) and are told to
// the ranks that list them, in the next message. Spatial indices are not sent: each is rebuilt
// beside the previous arrival's or a local map's (ParticleMap's near constructor), as a loaded
// state's are. Design and costs: docs/distributed.md.
// Thread safety: thread-compatible, and collective (every rank calls it at the same step).
// Costs: O(M / R) plus the nodes sent and received, the arrivals' index changes and a sweep of
// the named nodes (a read of each one's count); one exchange of R messages a rank.
#pragma once

#include <cstdint>
#include <span>

#include "engine/internal/filter_state.h"
#include "parallel/particle_kernel.h"

namespace fastslam::engine::internal {

// What one exchange moved, from this rank.
struct ExchangeCounts {
  std::uint64_t particles_sent = 0;  // distinct particles sent (each with its copy count)
  std::uint64_t copies_sent = 0;     // outputs filled on other ranks
  std::uint64_t bytes_sent = 0;
  // What sending every copy with its whole map would cost: copies x (pose + landmarks).
  std::uint64_t naive_bytes = 0;
};

// REQUIRES: s.group; `ends` of s.store.size() entries and `start` from draw_ranges over the set.
// Throws std::logic_error when a message does not parse (ranks built from different programs:
// a rank's own failure, which the others cannot know of), and what the heap throws.
ExchangeCounts exchange_particles(FilterState& s, const parallel::ParticleKernel& kernel,
                                  std::uint64_t start, std::span<const std::uint64_t> ends,
                                  std::size_t grain);

}  // namespace fastslam::engine::internal
