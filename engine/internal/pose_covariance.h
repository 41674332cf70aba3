// The particles' state covariances of FastSLAM 2.0 (N x N, column-major, in slots of 25 doubles,
// one slot per particle): the motion's since the last scan and, without odometry, the
// velocities' left by the scan's draw (engine/proposal.h draw_state). Every read and write of
// them goes through this class: the motion pass and the known-id proposal move a block's upper
// triangles into lane columns and back, the unknown-id pass reads and writes one particle's
// matrix. They live in the particle store's covariance column, which resampling gathers when
// they outlive a scan (without odometry).
// Thread safety: thread-compatible; concurrent calls on disjoint particles are safe.
// Costs: O(N^2) per particle, no allocation.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <utility>

#include <Eigen/Core>

#include "memory/particle_store.h"

namespace fastslam::engine::internal {

class PoseCovariances {
 public:
  static constexpr std::size_t kSlot = memory::ParticleStore::kPoseCovStride;  // N <= 5

  // A view of `store`'s covariance column (StoreOptions::pose_covariance), which resampling
  // gathers with the particles when it is carried; empty for FastSLAM 1.0.
  explicit PoseCovariances(memory::ParticleStore& store) : store_(&store) {}

  // Particle i's N x N matrix.
  template <int N>
  Eigen::Map<Eigen::Matrix<double, N, N>> at(std::size_t i) {
    return Eigen::Map<Eigen::Matrix<double, N, N>>(&values()[i * kSlot]);
  }

  // Upper-triangle entry e = (row, c), row <= c, in row-major order, of particles
  // [begin, begin + count) into lanes[e][0, count).
  template <int N>
  void load_upper(std::size_t begin, std::size_t count, double* const* lanes) const {
    const std::span<const double> v = values();
    for (int row = 0, e = 0; row < N; ++row) {
      for (int c = row; c < N; ++c, ++e) {
        for (std::size_t l = 0; l < count; ++l) lanes[e][l] = v[(begin + l) * kSlot + c * N + row];
      }
    }
  }

  // The inverse of load_upper, mirrored into the lower triangle.
  template <int N>
  void store_upper(std::size_t begin, std::size_t count, const double* const* lanes) {
    const std::span<double> v = values();
    for (int row = 0, e = 0; row < N; ++row) {
      for (int c = row; c < N; ++c, ++e) {
        for (std::size_t l = 0; l < count; ++l) {
          double* p = &v[(begin + l) * kSlot];
          p[c * N + row] = p[row * N + c] = lanes[e][l];
        }
      }
    }
  }

  // Zeroes the slots of particles [begin, begin + count).
  void clear(std::size_t begin, std::size_t count) {
    std::fill_n(&values()[begin * kSlot], count * kSlot, 0.0);
  }

  // Every slot, in particle order; empty when the store keeps none (state_io.h saves zeros).
  std::span<double> values() { return store_->pose_cov(); }
  std::span<const double> values() const { return std::as_const(*store_).pose_cov(); }

 private:
  memory::ParticleStore* store_;
};

}  // namespace fastslam::engine::internal
