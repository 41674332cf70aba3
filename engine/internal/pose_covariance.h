// The particles' state covariances of FastSLAM 2.0 (N x N, column-major, in slots of 25 doubles,
// one slot per particle): the motion's since the last scan and, without odometry, the
// velocities' left by the scan's draw (engine/proposal.h draw_state). Every read and write of
// them goes through this class: the motion pass and the known-id proposal move a block's upper
// triangles into lane columns and back, the unknown-id pass reads and writes one particle's
// matrix, and resampling hands each descendant its ancestor's slot.
// Thread safety: thread-compatible; concurrent calls on disjoint particles are safe, except
// `follow`. Costs: O(N^2) per particle; `follow` O(M) and reuses its gather buffer.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include <Eigen/Core>

namespace fastslam::engine::internal {

class PoseCovariances {
 public:
  static constexpr std::size_t kSlot = 25;  // doubles per particle (N <= 5)

  explicit PoseCovariances(std::size_t particles) : values_(particles * kSlot, 0.0) {}

  // Particle i's N x N matrix.
  template <int N>
  Eigen::Map<Eigen::Matrix<double, N, N>> at(std::size_t i) {
    return Eigen::Map<Eigen::Matrix<double, N, N>>(&values_[i * kSlot]);
  }

  // Upper-triangle entry e = (row, c), row <= c, in row-major order, of particles
  // [begin, begin + count) into lanes[e][0, count).
  template <int N>
  void load_upper(std::size_t begin, std::size_t count, double* const* lanes) const {
    for (int row = 0, e = 0; row < N; ++row) {
      for (int c = row; c < N; ++c, ++e) {
        for (std::size_t l = 0; l < count; ++l) {
          lanes[e][l] = values_[(begin + l) * kSlot + c * N + row];
        }
      }
    }
  }

  // The inverse of load_upper, mirrored into the lower triangle.
  template <int N>
  void store_upper(std::size_t begin, std::size_t count, const double* const* lanes) {
    for (int row = 0, e = 0; row < N; ++row) {
      for (int c = row; c < N; ++c, ++e) {
        for (std::size_t l = 0; l < count; ++l) {
          double* p = &values_[(begin + l) * kSlot];
          p[c * N + row] = p[row * N + c] = lanes[e][l];
        }
      }
    }
  }

  // Zeroes the slots of particles [begin, begin + count).
  void clear(std::size_t begin, std::size_t count) {
    std::fill_n(&values_[begin * kSlot], count * kSlot, 0.0);
  }

  // After resampling: descendant i takes the slot of particle ancestors[i].
  void follow(std::span<const std::uint32_t> ancestors) {
    scratch_.resize(values_.size());
    for (std::size_t i = 0; i < ancestors.size(); ++i) {
      std::copy_n(&values_[std::size_t{ancestors[i]} * kSlot], kSlot, &scratch_[i * kSlot]);
    }
    values_.swap(scratch_);
  }

  // Every slot, in particle order (state_io.h saves and loads them).
  std::vector<double>& values() { return values_; }
  const std::vector<double>& values() const { return values_; }

 private:
  std::vector<double> values_;
  std::vector<double> scratch_;  // follow's gather
};

}  // namespace fastslam::engine::internal
