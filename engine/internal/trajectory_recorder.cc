#include "engine/internal/trajectory_recorder.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace fastslam::engine::internal {

void TrajectoryRecorder::begin(std::span<const double> log_weight, std::size_t controls) {
  // Every entry is written by the motion pass (record_poses): no need to clear it.
  recorded_.resize(controls * log_weight.size() * 4);
  const double max_lw = *std::max_element(log_weight.begin(), log_weight.end());
  weights_.resize(log_weight.size());
  for (std::size_t i = 0; i < log_weight.size(); ++i) {
    weights_[i] = std::exp(log_weight[i] - max_lw);
  }
}

void TrajectoryRecorder::finish(const parallel::ParticleKernel& kernel, std::size_t controls,
                                std::uint64_t first_control) {
  using Sums = std::array<double, 5>;
  const std::size_t m = weights_.size();
  for (std::size_t k = 0; k < controls; ++k) {
    const double* rec = &recorded_[k * m * 4];
    const Sums sums = kernel.reduce(
        m, Sums{},
        [&](std::size_t begin, std::size_t end) {
          Sums part{};
          for (std::size_t i = begin; i < end; ++i) {
            const double w = weights_[i];
            part[0] += w;
            for (int c = 0; c < 4; ++c) part[c + 1] += w * rec[i * 4 + c];
          }
          return part;
        },
        [](const Sums& a, const Sums& b) {
          return Sums{a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3], a[4] + b[4]};
        });
    points_.push_back(
        {first_control + k, sums[1] / sums[0], sums[2] / sums[0], std::atan2(sums[4], sums[3])});
  }
}

}  // namespace fastslam::engine::internal
