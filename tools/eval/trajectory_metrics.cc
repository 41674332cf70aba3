#include "tools/eval/trajectory_metrics.h"

#include <algorithm>
#include <cmath>
#include <span>
#include <stdexcept>
#include <string>

#include "engine/angles.h"

namespace fastslam::tools {
namespace {

bool finite(const StampedPose& p, bool heading) {
  return std::isfinite(p.time) && std::isfinite(p.x) && std::isfinite(p.y) &&
         (!heading || std::isfinite(p.theta));
}

// sum |(R(angle) - I) a - d|^2 from sum |a|^2, sum |d|^2, sum a.d and sum a x d: the terms are
// as small as the errors, so no large sums cancel (1 - cos by the half-angle form).
double rotated_residual(double angle, double aa, double dd, double ad_dot, double ad_cross) {
  const double half = std::sin(0.5 * angle);
  const double one_minus_cos = 2.0 * half * half;
  const double se = 2.0 * one_minus_cos * (aa + ad_dot) - 2.0 * std::sin(angle) * ad_cross + dd;
  return std::max(se, 0.0);
}

}  // namespace

TrajectoryEvaluator::TrajectoryEvaluator(const TrajectoryEvaluatorOptions& options)
    : options_(options) {
  if (!std::isfinite(options.rpe_delta) || !(options.rpe_delta > 0)) {
    throw std::invalid_argument("TrajectoryEvaluator: rpe_delta must be finite and > 0");
  }
  if (std::isnan(options.max_reference_delay) || options.max_reference_delay < 0) {
    throw std::invalid_argument("TrajectoryEvaluator: max_reference_delay must be >= 0");
  }
}

void TrajectoryEvaluator::add_estimate(const StampedPose& estimate) {
  if (!finite(estimate, true)) {
    throw std::invalid_argument("TrajectoryEvaluator: estimate at time " +
                                std::to_string(estimate.time) + " is not finite");
  }
  if (head_ < estimates_.size() && estimate.time < estimates_.back().time) {
    throw std::invalid_argument("TrajectoryEvaluator: estimate at time " +
                                std::to_string(estimate.time) + " is out of time order");
  }
  estimates_.push_back(estimate);
  // Every estimate at or before a pending reference's time is now in: pair it.
  while (!pending_.empty() && pending_.front().time < estimate.time) {
    resolve(pending_.front(), sums_);
    pending_.pop_front();
  }
  prune();
}

void TrajectoryEvaluator::add_reference(const StampedPose& reference) {
  if (!finite(reference, options_.reference_heading)) {
    throw std::invalid_argument("TrajectoryEvaluator: reference at time " +
                                std::to_string(reference.time) + " is not finite");
  }
  if (reference.time < last_reference_) {
    throw std::invalid_argument("TrajectoryEvaluator: reference at time " +
                                std::to_string(reference.time) + " is out of time order");
  }
  if (dropped_ && reference.time < estimates_[head_].time) {
    throw std::logic_error("TrajectoryEvaluator: reference at time " +
                           std::to_string(reference.time) +
                           " trails the estimates by more than max_reference_delay");
  }
  last_reference_ = reference.time;
  // Pending references are never older than the newest estimate, so order is kept.
  if (head_ < estimates_.size() && estimates_.back().time > reference.time) {
    resolve(reference, sums_);
  } else {
    pending_.push_back(reference);
  }
  prune();
}

void TrajectoryEvaluator::resolve(const StampedPose& reference, Sums& sums) const {
  const std::optional<StampedPose> estimate =
      pose_at(std::span(estimates_).subspan(head_), reference.time);
  if (estimate) {
    sums.add(*estimate, reference, options_);
  } else {
    ++sums.raw.skipped;
  }
}

// pose_at(t) reads only the last sample at or before t and those after it. Every reference
// still to come is at or after `horizon`: the pending ones and later ones by time order, and
// by contract none trails the newest estimate by more than max_reference_delay.
void TrajectoryEvaluator::prune() {
  if (head_ >= estimates_.size()) return;
  const double next_reference = pending_.empty() ? last_reference_ : pending_.front().time;
  const double horizon =
      std::max(estimates_.back().time - options_.max_reference_delay, next_reference);
  while (estimates_.size() - head_ >= 2 && estimates_[head_ + 1].time <= horizon) {
    ++head_;
    dropped_ = true;
  }
  // Amortised O(1): move the live tail down once the dead head is at least as long.
  if (head_ >= 64 && 2 * head_ >= estimates_.size()) {
    estimates_.erase(estimates_.begin(), estimates_.begin() + static_cast<std::ptrdiff_t>(head_));
    head_ = 0;
  }
}

void TrajectoryEvaluator::Sums::add(const StampedPose& p, const StampedPose& q,
                                    const TrajectoryEvaluatorOptions& options) {
  // Raw errors, summed in reference order as position_errors() does.
  const double d2 = (p.x - q.x) * (p.x - q.x) + (p.y - q.y) * (p.y - q.y);
  const double d = std::sqrt(d2);
  raw_se += d2;
  raw_sum += d;
  raw_max = std::max(raw_max, d);
  raw.last = d;
  ++raw.used;

  // Welford co-moments of a = p and d = q - p: sum (x - old mean)(y - new mean).
  const auto n = static_cast<double>(raw.used);
  const double da[2] = {p.x - mean_a[0], p.y - mean_a[1]};
  mean_a[0] += da[0] / n;
  mean_a[1] += da[1] / n;
  const double diff[2] = {q.x - p.x, q.y - p.y};
  const double dd_old[2] = {diff[0] - mean_d[0], diff[1] - mean_d[1]};
  mean_d[0] += dd_old[0] / n;
  mean_d[1] += dd_old[1] / n;
  const double rd[2] = {diff[0] - mean_d[0], diff[1] - mean_d[1]};
  aa += da[0] * (p.x - mean_a[0]) + da[1] * (p.y - mean_a[1]);
  dd += dd_old[0] * rd[0] + dd_old[1] * rd[1];
  ad_dot += da[0] * rd[0] + da[1] * rd[1];
  ad_cross += da[0] * rd[1] - da[1] * rd[0];

  // RPE pairs as evo's filter_pairs_by_path: the first anchor is the first reference whose
  // path from the first one reaches delta; each next one the first whose path from the
  // previous anchor does. Path steps as np.linalg.norm.
  if (!started) {
    started = true;
  } else {
    path += std::sqrt((q.x - previous[0]) * (q.x - previous[0]) +
                      (q.y - previous[1]) * (q.y - previous[1]));
  }
  previous[0] = q.x;
  previous[1] = q.y;
  if (path < options.rpe_delta) return;
  path = 0.0;
  if (anchor_estimate) {
    const StampedPose& pi = *anchor_estimate;
    const StampedPose& qi = *anchor_reference;
    const double dp[2] = {p.x - pi.x, p.y - pi.y};
    const double dq[2] = {q.x - qi.x, q.y - qi.y};
    if (options.reference_heading) {
      // E = (Qi^-1 Qj)^-1 (Pi^-1 Pj): |t(E)| = |Ri^T dp - Si^T dq| (a rotation keeps norms).
      const double cp = std::cos(pi.theta), sp = std::sin(pi.theta);
      const double cq = std::cos(qi.theta), sq = std::sin(qi.theta);
      const double ex = (cp * dp[0] + sp * dp[1]) - (cq * dq[0] + sq * dq[1]);
      const double ey = (-sp * dp[0] + cp * dp[1]) - (-sq * dq[0] + cq * dq[1]);
      trans_se += ex * ex + ey * ey;
      const double rot = engine::wrap_angle(engine::wrap_angle(p.theta - pi.theta) -
                                            engine::wrap_angle(q.theta - qi.theta));
      rot_se += rot * rot;
    } else {
      const double u[2] = {dq[0] - dp[0], dq[1] - dp[1]};
      pp += dp[0] * dp[0] + dp[1] * dp[1];
      uu += u[0] * u[0] + u[1] * u[1];
      pu_dot += dp[0] * u[0] + dp[1] * u[1];
      pu_cross += dp[0] * u[1] - dp[1] * u[0];
    }
    ++pairs;
  }
  anchor_estimate = p;
  anchor_reference = q;
}

TrajectoryMetrics TrajectoryEvaluator::finish() const {
  Sums s = sums_;
  for (const StampedPose& reference : pending_) resolve(reference, s);

  TrajectoryMetrics m;
  m.raw = s.raw;
  m.rpe.delta = options_.rpe_delta;
  m.rpe.pairs = s.pairs;
  if (options_.reference_heading) m.rpe.rotation_rmse = 0.0;
  if (s.raw.used == 0) return m;
  const auto n = static_cast<double>(s.raw.used);
  m.raw.rmse = std::sqrt(s.raw_se / n);
  m.raw_mean = s.raw_sum / n;
  m.raw_max = s.raw_max;

  // Horn/Umeyama in 2-D: the angle maximising sum (R a_c) . b_c with b = a + d.
  const double angle = std::atan2(s.ad_cross, s.aa + s.ad_dot);
  m.aligned.rotation = angle;
  m.aligned.rmse = std::sqrt(rotated_residual(angle, s.aa, s.dd, s.ad_dot, s.ad_cross) / n);
  const double c = std::cos(angle), sn = std::sin(angle);
  const double reference_mean[2] = {s.mean_a[0] + s.mean_d[0], s.mean_a[1] + s.mean_d[1]};
  m.aligned.x = reference_mean[0] - (c * s.mean_a[0] - sn * s.mean_a[1]);
  m.aligned.y = reference_mean[1] - (sn * s.mean_a[0] + c * s.mean_a[1]);

  if (s.pairs > 0) {
    const auto pairs = static_cast<double>(s.pairs);
    if (options_.reference_heading) {
      m.rpe.translation_rmse = std::sqrt(s.trans_se / pairs);
      m.rpe.rotation_rmse = std::sqrt(s.rot_se / pairs);
    } else {
      // Displacements compared after the ATE alignment's rotation (the reference has none).
      m.rpe.translation_rmse =
          std::sqrt(rotated_residual(angle, s.pp, s.uu, s.pu_dot, s.pu_cross) / pairs);
    }
  }
  return m;
}

}  // namespace fastslam::tools
