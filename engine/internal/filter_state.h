// The state of a Filter that outlives a call: configuration, node heap, particles and their maps,
// FastSLAM 2.0 covariances, the queue of controls, the known-id table, the counters, the clock
// and the last scan's report. The
// stages read and change it; the Filter facade (engine/filter.cc) owns it, and state_io.h saves
// and loads it. Thread safety: thread-compatible; the passes change disjoint particles
// concurrently and `phase_times` per thread. Costs: construction O(M).
#pragma once

#include <cstdint>
#include <memory>
#include <unordered_set>
#include <vector>

#include <Eigen/Core>
#include <oneapi/tbb/combinable.h>

#include "engine/filter_config.h"
#include "engine/internal/pose_covariance.h"
#include "engine/internal/scan_plan.h"
#include "engine/internal/scan_report.h"
#include "engine/measurement_model.h"
#include "memory/node_heap.h"
#include "memory/node_registry.h"
#include "memory/particle_store.h"
#include "parallel/collective.h"

namespace fastslam::engine::internal {

// Per-thread time and counts of the passes (FilterStatistics sums them).
struct PhaseTimes {
  double predict = 0.0;
  double associate = 0.0;
  double update = 0.0;
  std::uint64_t created = 0;  // landmarks started, summed over particles
  std::uint64_t removed = 0;  // landmarks removed by negative information
};

struct FilterCounters {
  std::uint64_t step = 0;  // events so far (controls and scans): keys the random streams
  std::uint64_t controls = 0, scans = 0, observations = 0, resamples = 0, weight_resets = 0;
  double resample_seconds = 0.0;
  double log_evidence = 0.0;
  // Landmarks started and removed before the state was loaded (the per-thread counts in
  // PhaseTimes hold those since).
  std::uint64_t landmarks_created = 0, landmarks_removed = 0;
  double observe_wall_seconds = 0.0;
};

// What a rank's resamplings sent to other ranks (a shared set; statistics only).
struct ExchangeTotals {
  std::uint64_t particles = 0, copies = 0, bytes = 0, naive_bytes = 0;
  double seconds = 0.0;
};

// What a rank of a shared set knows of the node names that let the particle exchange skip the
// nodes a receiver holds (engine/internal/particle_exchange.h; docs/distributed.md).
struct NodeLinks {
  NodeLinks(memory::NodeHeap& heap, int rank, int ranks)
      : registry(heap, static_cast<std::uint64_t>(rank) + 1), held_by(ranks), retired_for(ranks) {}
  memory::NodeRegistry registry;
  // Per rank: the names it holds as far as this rank knows (sent to it or received from it,
  // and not retired since; pinned names are held everywhere and not listed).
  std::vector<std::unordered_set<memory::NodeId>> held_by;
  // Per rank: names this rank retired that it lists in held_by, to tell it at the next exchange.
  std::vector<std::vector<memory::NodeId>> retired_for;
};

// The store a configuration needs: a spatial index per map for unknown association (known ids
// find landmarks by slot); FastSLAM 2.0's covariances, carried through resampling without
// odometry, where the velocities' covariance outlives the scan (draw_state).
memory::StoreOptions store_options(const FilterConfig& config);

struct FilterState {
  // REQUIRES: validate(config) passed. With a group, this rank's share of config.particles
  // (parallel::particle_share; throws std::invalid_argument when the set is too small to deal).
  explicit FilterState(const FilterConfig& c, parallel::Collective* group = nullptr);
  FilterState(const FilterConfig& c, parallel::Collective* group, parallel::ParticleShare share);

  FilterConfig config;
  // The ranks sharing the particle set (nullptr: the store holds all of it), and the set's
  // index of local particle 0, which keys the particles' random streams.
  parallel::Collective* group;
  std::uint32_t first_particle;
  memory::PoolHeap heap;  // before the store: outlives every map
  std::unique_ptr<NodeLinks> links;  // with a group
  memory::ParticleStore store;
  PoseCovariances covariances;
  RangeBearingModel sensor;
  Eigen::Matrix2d r;  // the measurement noise
  std::vector<PendingControl> pending;
  KnownSlots known_slots;
  // Unknown association: a bound on every landmark covariance's largest eigenvalue (the largest
  // of eq. 70 over the observations seen so far, and of set_map's), for the candidate search.
  double landmark_variance_bound = 0.0;
  FilterCounters counters;
  ExchangeTotals exchange;
  // The clock (Estimate::time): the data's time; `timed` once a time was given.
  double time = 0.0;
  bool timed = false;
  ScanRecords records;                               // the scan being processed, per particle
  std::vector<ObservationAssociation> associations;  // the last scan's report
  mutable tbb::combinable<PhaseTimes> phase_times;   // combine_each is not const
};

}  // namespace fastslam::engine::internal
