// The particles of a filter, stored as columns (structure of arrays).
//
// Columns: pose x, y, theta; velocities v, omega (for the no-odometry models, eq. 79-81; the
// `omega` column holds the curvature kappa for engine::MotionKind::kBrownianCurvature); the
// log-weight; each particle's map (a persistent `LandmarkTree`, whose size is the particle's
// landmark count); and each particle's spatial index over that map (a persistent
// `SpatialIndex`, empty unless the engine keeps one: unknown data association). The numeric
// columns are cache-line aligned, so loops over particles vectorise. Resampling is `gather`:
// particle k of the result is particle index[k] of the input; a map or index is shared by
// bumping its root's count, and every tree that no output particle holds is released exactly
// once (by its reference count), in parallel.
//
// Ownership: the store owns its columns and one reference to each particle's map and index;
// it borrows the `NodeHeap` (which must outlive it).
// Thread safety: thread-compatible. Distinct particles (columns entries, maps) may be written
// by distinct threads at once; `gather` and `resize` need exclusive use of the store.
// Costs: `gather` is O(M) time plus the frees of the maps that die, runs over TBB in the
// caller's arena, and allocates the new columns (O(M)); column access is O(1).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <oneapi/tbb/cache_aligned_allocator.h>

#include "memory/landmark_tree.h"
#include "memory/node_heap.h"
#include "memory/spatial_index.h"

namespace fastslam::memory {

class ParticleStore {
 public:
  using Column = std::vector<double, tbb::cache_aligned_allocator<double>>;

  // `particles` particles at the origin with zero velocity, log-weight 0 and empty maps.
  ParticleStore(std::size_t particles, NodeHeap& heap);

  std::size_t size() const noexcept { return maps_.size(); }
  NodeHeap& heap() const noexcept { return *heap_; }

  std::span<double> x() noexcept { return x_; }
  std::span<double> y() noexcept { return y_; }
  std::span<double> theta() noexcept { return theta_; }
  std::span<double> v() noexcept { return v_; }
  std::span<double> omega() noexcept { return omega_; }
  std::span<double> log_weight() noexcept { return log_weight_; }
  std::span<const double> x() const noexcept { return x_; }
  std::span<const double> y() const noexcept { return y_; }
  std::span<const double> theta() const noexcept { return theta_; }
  std::span<const double> v() const noexcept { return v_; }
  std::span<const double> omega() const noexcept { return omega_; }
  std::span<const double> log_weight() const noexcept { return log_weight_; }

  LandmarkTree& map(std::size_t particle) noexcept { return maps_[particle]; }
  const LandmarkTree& map(std::size_t particle) const noexcept { return maps_[particle]; }
  SpatialIndex& index(std::size_t particle) noexcept { return indices_[particle]; }
  const SpatialIndex& index(std::size_t particle) const noexcept { return indices_[particle]; }
  std::size_t landmark_count(std::size_t particle) const noexcept {
    return maps_[particle].size();
  }

  // Resampling: afterwards particle k is a copy of former particle index[k], for every k, and
  // the store holds index.size() particles. Throws std::invalid_argument naming the first bad
  // entry when an index is out of range, and then leaves the store unchanged.
  // `grain` is the number of particles per parallel task.
  void gather(std::span<const std::uint32_t> index, std::size_t grain = 256);

 private:
  NodeHeap* heap_;
  Column x_, y_, theta_, v_, omega_, log_weight_;
  std::vector<LandmarkTree> maps_;
  std::vector<SpatialIndex> indices_;
};

}  // namespace fastslam::memory
