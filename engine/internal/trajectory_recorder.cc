#include "engine/internal/trajectory_recorder.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <cstring>
#include <span>
#include <utility>

#include "engine/internal/weight_range.h"
#include "parallel/vector_math.h"

namespace fastslam::engine::internal {
namespace {

constexpr std::size_t kG = TrajectorySums::kGroup;
constexpr std::size_t kT = TrajectorySums::kTerms;

// One fixed order for a group's eight terms, ((p0 + p4) + (p2 + p6)) + ((p1 + p5) + (p3 + p7)):
// the first step as one four-wide add (GCC's vector extension, so that it is not left scalar).
// The file compiles without contraction (engine/CMakeLists.txt): each product is rounded before
// the adds, so the bits are the same on every target and in any vectorisation.
using Four = double __attribute__((vector_size(32)));
[[gnu::always_inline]] inline double group_total(const double* p) {
  Four lo;
  Four hi;
  std::memcpy(&lo, p, sizeof(Four));
  std::memcpy(&hi, p + 4, sizeof(Four));
  const Four q = lo + hi;
  return (q[0] + q[2]) + (q[1] + q[3]);
}

// The smallest and largest log weight, the values std::minmax_element gives. A NaN makes its
// result depend on where the NaN sits, so that input goes to the library.
std::pair<double, double> log_weight_range(std::span<const double> l) {
  const SelectRange r = select_range(l);
  if (r.nan) {
    const auto [lo, hi] = std::minmax_element(l.begin(), l.end());
    return {*lo, *hi};
  }
  return {r.low, r.high};
}

}  // namespace

void TrajectorySums::weights(std::size_t begin, std::size_t lanes, double* w) const {
  assert(begin % kG == 0 && lanes % kG == 0);
  const std::size_t real =
      begin < log_weight.size() ? std::min(lanes, log_weight.size() - begin) : 0;
  // shift is the largest log-weight; exp_nonpositive gives the same bits with any C library
  // (and exactly 1 at 0, which a uniform set skips computing).
  if (uniform) {
    std::fill(w, w + real, 1.0);
  } else {
    for (std::size_t l = 0; l < real; ++l) {
      w[l] = parallel::exp_nonpositive(log_weight[begin + l] - shift);
    }
  }
  std::fill(w + real, w + lanes, 0.0);
}

void TrajectorySums::group_sums(std::size_t lanes, const double* x, const double* y,
                                const double* theta, const double* w, double* out) {
  assert(lanes % kG == 0);
  for (std::size_t at = 0; at < lanes; at += kG, out += kT) {
    double p[kT][kG];
    for (std::size_t l = 0; l < kG; ++l) {
      double c = 0.0;
      double s = 0.0;
      parallel::sincos(theta[at + l], c, s);
      const double wl = w[at + l];
      p[0][l] = wl;
      p[1][l] = wl * x[at + l];
      p[2][l] = wl * y[at + l];
      p[3][l] = wl * c;
      p[4][l] = wl * s;
    }
    for (std::size_t t = 0; t < kT; ++t) out[t] = group_total(p[t]);
  }
}

void TrajectorySums::add(std::size_t k, std::size_t begin, std::size_t lanes, const double* x,
                         const double* y, const double* theta, const double* w) const {
  assert(begin % kG == 0 && lanes % kG == 0);
  group_sums(lanes, x, y, theta, w, sums + ((k + 1) * groups + begin / kG) * kT);
}

void TrajectorySums::add_start(std::size_t begin, std::size_t lanes, const double* x,
                               const double* y, const double* theta, const double* w) const {
  assert(begin % kG == 0 && lanes % kG == 0);
  group_sums(lanes, x, y, theta, w, sums + (begin / kG) * kT);
}

void TrajectoryRecorder::begin(std::span<const double> log_weight, std::size_t controls) {
  const auto [low, high] = log_weight_range(log_weight);
  double max_lw = high;
  if (group_ != nullptr) {
    for (const double m : parallel::all_gather_value(*group_, max_lw)) max_lw = std::max(max_lw, m);
  }
  const std::size_t groups = (log_weight.size() + kG - 1) / kG;
  // The motion stage writes the slots finish() reads (TrajectorySums::add, add_start): no need
  // to clear them.
  sums_.resize((controls + 1) * groups * kT);
  view_ = {log_weight, max_lw, groups, low == max_lw, sums_.data()};
}

void TrajectoryRecorder::finish(std::size_t controls, std::uint64_t first_control,
                                std::span<const MotionRun> runs,
                                std::span<const Eigen::Vector3d> partial) {
  using Sums = std::array<double, kT>;
  // The slots to fold: each control's own, or (composed) each run's start and end.
  std::vector<std::size_t> slots;
  if (runs.empty()) {
    for (std::size_t k = 0; k < controls; ++k) slots.push_back(k + 1);
  } else {
    for (const MotionRun& run : runs) {
      if (run.count > 1 && (slots.empty() || slots.back() != run.first)) slots.push_back(run.first);
      slots.push_back(run.first + run.count);
    }
  }
  std::vector<Sums> total(controls + 1, Sums{});
  // Each slot's groups folded in the set's order: this process's, or rank by rank.
  auto fold = [&](const double* sums, std::size_t groups) {
    for (const std::size_t slot : slots) {
      for (std::size_t g = 0; g < groups; ++g) {
        const double* s = sums + (slot * groups + g) * kT;
        for (std::size_t t = 0; t < kT; ++t) total[slot][t] += s[t];
      }
    }
  };
  if (group_ == nullptr) {
    fold(sums_.data(), view_.groups);
  } else {
    std::vector<std::size_t> sizes;
    const parallel::Bytes all = group_->all_gather(std::as_bytes(std::span(sums_)), &sizes);
    std::vector<double> rank_sums;
    std::size_t at = 0;
    for (const std::size_t bytes : sizes) {
      rank_sums.resize(bytes / sizeof(double));
      std::memcpy(rank_sums.data(), all.data() + at, bytes);
      fold(rank_sums.data(), rank_sums.size() / kT / (controls + 1));
      at += bytes;
    }
  }
  auto point = [&](std::size_t k, const Sums& s) {
    points_.push_back({first_control + k, s[1] / s[0], s[2] / s[0], std::atan2(s[4], s[3])});
  };
  if (runs.empty()) {
    for (std::size_t k = 0; k < controls; ++k) point(k, total[k + 1]);
    return;
  }
  for (const MotionRun& run : runs) {
    const std::size_t last = run.first + run.count - 1;
    const Sums& b = total[run.first];
    for (std::size_t k = run.first; k < last; ++k) {
      // Each lane's position moves by R(theta) (d0, d1) and its heading by d2: the sums move
      // by the weighted cos and sin.
      const Eigen::Vector3d& d = partial[k];
      double c = 0.0;
      double s = 0.0;
      parallel::sincos(d[2], c, s);
      point(k, {b[0], b[1] + (d[0] * b[3] - d[1] * b[4]), b[2] + (d[0] * b[4] + d[1] * b[3]),
                c * b[3] - s * b[4], s * b[3] + c * b[4]});
    }
    point(last, total[last + 1]);
  }
}

}  // namespace fastslam::engine::internal
