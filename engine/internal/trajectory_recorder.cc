#include "engine/internal/trajectory_recorder.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>

namespace fastslam::engine::internal {

void TrajectoryRecorder::begin(std::span<const double> log_weight, std::size_t controls) {
  // Every entry is written by the motion pass (record_poses): no need to clear it.
  recorded_.resize(controls * log_weight.size() * 4);
  double max_lw = *std::max_element(log_weight.begin(), log_weight.end());
  if (group_ != nullptr) {
    for (const double m : parallel::all_gather_value(*group_, max_lw)) max_lw = std::max(max_lw, m);
  }
  // The shifted log-weights now (the pass changes the weights); finish() exponentiates them in
  // its parallel blocks.
  weights_.resize(log_weight.size());
  for (std::size_t i = 0; i < log_weight.size(); ++i) weights_[i] = log_weight[i] - max_lw;
}

void TrajectoryRecorder::finish(const parallel::ParticleKernel& kernel, std::size_t controls,
                                std::uint64_t first_control) {
  using Sums = std::array<double, 5>;
  const std::size_t m = weights_.size();
  constexpr std::size_t kBlock = parallel::ParticleKernel::kReduceBlock;
  const std::size_t blocks = (m + kBlock - 1) / kBlock;
  std::vector<Sums> mine(controls * blocks);
  // Controls [k0, k0 + G) of block b: each control's sums in particle order, as one control's
  // loop would add them, with G controls' additions interleaved so that they overlap.
  auto group_sums = [&]<std::size_t G>(std::size_t k0, std::size_t b, std::size_t begin,
                                       std::size_t end, double weight_sum) {
    std::array<std::array<double, 4>, G> part{};
    for (std::size_t i = begin; i < end; ++i) {
      const double w = weights_[i];
      for (std::size_t g = 0; g < G; ++g) {
        const double* rec = &recorded_[((k0 + g) * m + i) * 4];
        for (int c = 0; c < 4; ++c) part[g][c] += w * rec[c];
      }
    }
    for (std::size_t g = 0; g < G; ++g) {
      mine[(k0 + g) * blocks + b] = {weight_sum, part[g][0], part[g][1], part[g][2], part[g][3]};
    }
  };
  auto add = [](const Sums& a, const Sums& b) {
    return Sums{a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3], a[4] + b[4]};
  };
  auto record = [&](std::size_t k, const Sums& sums) {
    points_.push_back(
        {first_control + k, sums[1] / sums[0], sums[2] / sums[0], std::atan2(sums[4], sums[3])});
  };
  // Every control's block sums in one parallel call (a call per control costs more than its
  // work at small M), then each control folded over the blocks in order, as kernel.reduce folds
  // its blocks: the same bits for any thread count. A rank of a shared set gathers every rank's
  // blocks (rank r's blocks, control by control) and folds the set's blocks in order.
  kernel.for_each_fixed_block(m, kBlock, [&](std::size_t b, std::size_t begin, std::size_t end) {
    double weight_sum = 0.0;  // the same for every control
    for (std::size_t i = begin; i < end; ++i) {
      weights_[i] = std::exp(weights_[i]);
      weight_sum += weights_[i];
    }
    std::size_t k = 0;
    for (; k + 4 <= controls; k += 4)
      group_sums.template operator()<4>(k, b, begin, end, weight_sum);
    for (; k < controls; ++k) group_sums.template operator()<1>(k, b, begin, end, weight_sum);
  });
  std::vector<Sums> sums(controls, Sums{});
  if (group_ == nullptr) {
    for (std::size_t k = 0; k < controls; ++k) {
      for (std::size_t b = 0; b < blocks; ++b) sums[k] = add(sums[k], mine[k * blocks + b]);
    }
  } else {
    std::vector<std::size_t> sizes;
    const parallel::Bytes all = group_->all_gather(std::as_bytes(std::span(mine)), &sizes);
    std::size_t at = 0;
    for (const std::size_t bytes : sizes) {
      const std::size_t rank_blocks = controls == 0 ? 0 : bytes / sizeof(Sums) / controls;
      for (std::size_t k = 0; k < controls; ++k) {
        for (std::size_t b = 0; b < rank_blocks; ++b) {
          Sums block;
          std::memcpy(&block, all.data() + at + (k * rank_blocks + b) * sizeof(Sums), sizeof(Sums));
          sums[k] = add(sums[k], block);
        }
      }
      at += bytes;
    }
  }
  for (std::size_t k = 0; k < controls; ++k) record(k, sums[k]);
}

}  // namespace fastslam::engine::internal
