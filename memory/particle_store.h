// The particles of a filter, stored as columns (structure of arrays): pose x, y, theta;
// velocities v, omega (the no-odometry models; `omega` holds the curvature for
// engine::MotionKind::kBrownianCurvature); the log-weight; each particle's ParticleMap; and,
// when asked for at construction, each particle's state covariance (kPoseCovStride doubles).
// The numeric columns are cache-line aligned, so loops over particles vectorise. Resampling is
// `gather`: particle k of the result is particle index[k] of the input, every column with it
// (a map moved to the input's first output and copied, by bumping its roots' counts, to the
// others); trees no output particle holds are released, once each.
// Ownership: the store owns its columns and one reference to each particle's map; it borrows
// the `NodeHeap` (which must outlive it).
// Thread safety: thread-compatible. Distinct particles (column entries, maps) may be written by
// distinct threads at once; `gather` needs exclusive use of the store.
// Costs: column access O(1); `gather` O(M) plus the frees of the maps that die, in parallel
// over TBB in the caller's arena after one serial pass over the indices, allocating the new
// columns (O(M)); it keeps a second vector of M (empty) maps to gather into.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <oneapi/tbb/cache_aligned_allocator.h>

#include "memory/node_heap.h"
#include "memory/particle_map.h"

namespace fastslam::memory {

// What the store keeps of each particle's state covariance (FastSLAM 2.0's proposal).
enum class PoseCovariance {
  kNone,     // no column
  kScratch,  // a column `gather` leaves in place: its entries matter within a step only
  kCarried,  // a column `gather` moves with its particle
};

struct StoreOptions {
  Indexing indexing = Indexing::kNone;  // of every particle's map
  PoseCovariance pose_covariance = PoseCovariance::kNone;
};

class ParticleStore {
 public:
  using Column = std::vector<double, tbb::cache_aligned_allocator<double>>;
  // Doubles per particle in the covariance column: room for the largest state (5 x 5).
  static constexpr std::size_t kPoseCovStride = 25;

  // `particles` particles at the origin with zero velocity, log-weight 0, empty maps and (when
  // kept) zero covariances.
  ParticleStore(std::size_t particles, NodeHeap& heap, StoreOptions options = {});

  std::size_t size() const noexcept { return maps_.size(); }
  NodeHeap& heap() const noexcept { return *heap_; }
  const StoreOptions& options() const noexcept { return options_; }

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
  // Particle i's covariance is [i * kPoseCovStride, (i + 1) * kPoseCovStride); empty when the
  // store keeps none.
  std::span<double> pose_cov() noexcept { return pose_cov_; }
  std::span<const double> pose_cov() const noexcept { return pose_cov_; }

  ParticleMap& map(std::size_t particle) noexcept { return maps_[particle]; }
  const ParticleMap& map(std::size_t particle) const noexcept { return maps_[particle]; }
  // An empty map of this store's heap and indexing.
  ParticleMap empty_map() const noexcept { return ParticleMap(*heap_, options_.indexing); }
  std::size_t landmark_count(std::size_t particle) const noexcept { return maps_[particle].size(); }

  // Adds `count` particles after the others, as the constructor makes them: room for
  // particles arriving from another rank before a gather. O(M + count) (columns may move).
  void append(std::size_t count);

  // Resampling: afterwards particle k is a copy of former particle index[k], for every k, and
  // the store holds index.size() particles. Throws std::invalid_argument naming the first bad
  // entry when an index is out of range, std::length_error for 2^32 or more outputs, and then
  // leaves the store unchanged.
  // `grain` is the number of particles per parallel task.
  void gather(std::span<const std::uint32_t> index, std::size_t grain = 256);

 private:
  NodeHeap* heap_;
  StoreOptions options_;
  Column x_, y_, theta_, v_, omega_, log_weight_;
  Column pose_cov_;
  Column pose_cov_spare_;  // kCarried: the gather's target, kept to reuse its allocation
  std::vector<ParticleMap> maps_;
  std::vector<ParticleMap> maps_spare_;  // the gather's target: empty maps between gathers
  static constexpr std::uint32_t kNoChild = 0xFFFFFFFFu;
  std::vector<std::uint32_t> first_child_;  // the gather's first output of each input
};

}  // namespace fastslam::memory
