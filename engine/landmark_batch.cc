#include "engine/landmark_batch.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <type_traits>

#include "engine/angles.h"
#include "engine/landmark_ekf.h"
#include "engine/proposal.h"
#include "parallel/vector_math.h"

namespace fastslam::engine {
namespace {

using parallel::arctan2;
using parallel::log_positive;
using parallel::select;

// Lanes per pass of the vector loop: bounds the stack flags of the lanes that fall back.
constexpr std::size_t kChunk = 64;

// One exact step of wrap_angle for a within one turn of (-pi, pi]: a select between constants,
// the subtraction unconditional (a - 0 == a), so the loop if-converts.
[[gnu::always_inline]] inline double wrap_step(double a) noexcept {
  const double shift = select(a > kPi, kTwoPi, 0.0) - select(a <= -kPi, kTwoPi, 0.0);
  return a - shift;
}

// The terms one lane's update and proposal share: the sensor position, the innovation
// (v0, v1), G_mu, A = G_mu Sigma and Q = G_mu Sigma G_mu^T + R (symmetrised as
// evaluate_observation does); `good` is false where the lane must take the scalar path.
struct LaneTerms {
  double sx, sy, dx, dy, inv_q, inv_r, v0, v1;
  double g00, g01, g10, g11, a00, a01, a10, a11, q00, q01, q11;
  bool good;
};

template <bool kOffset>
[[gnu::always_inline]] inline LaneTerms lane_terms(const SensorOffset& off, double yaw, double r00,
                                                   double r01, double r11, double z0, double z1,
                                                   double x, double y, double th, double mx,
                                                   double my, double cxx, double cxy,
                                                   double cyy) noexcept {
  LaneTerms t;
  t.sx = x;
  t.sy = y;
  t.good = std::fabs(th) <= kPi;
  if constexpr (kOffset) {
    double c = 0.0;
    double s = 0.0;
    parallel::sincos(th, c, s);
    t.sx = t.sx + (off.x * c - off.y * s);
    t.sy = t.sy + (off.x * s + off.y * c);
  }
  t.dx = mx - t.sx;
  t.dy = my - t.sy;
  const double q = t.dx * t.dx + t.dy * t.dy;
  const double range = std::sqrt(q);
  t.inv_q = 1.0 / q;
  t.inv_r = range * t.inv_q;
  // Bearing in [-pi, pi] minus a heading and a yaw in (-pi, pi]: two exact steps wrap it.
  const double bearing = wrap_step(wrap_step(arctan2(t.dy, t.dx) - th - yaw));
  t.v0 = z0 - range;
  t.v1 = wrap_step(z1 - bearing);
  t.good = t.good & (q > 0.0) & (q < 1e300) & (t.v1 > -kPi) & (t.v1 <= kPi);
  t.g00 = t.dx * t.inv_r;
  t.g01 = t.dy * t.inv_r;
  t.g10 = -t.dy * t.inv_q;
  t.g11 = t.dx * t.inv_q;
  t.a00 = t.g00 * cxx + t.g01 * cxy;
  t.a01 = t.g00 * cxy + t.g01 * cyy;
  t.a10 = t.g10 * cxx + t.g11 * cxy;
  t.a11 = t.g10 * cxy + t.g11 * cyy;
  t.q00 = t.a00 * t.g00 + t.a01 * t.g01 + r00;
  t.q01 = 0.5 * ((t.a00 * t.g10 + t.a01 * t.g11 + r01) + (t.a10 * t.g00 + t.a11 * t.g01 + r01));
  t.q11 = t.a10 * t.g10 + t.a11 * t.g11 + r11;
  return t;
}

// The scalar EKF of engine/landmark_ekf.h for one lane.
void update_lane_scalar(const RangeBearingModel& sensor, const Eigen::Matrix2d& r,
                        const Eigen::Vector2d& z, PoseLanes pose, LandmarkLanes lm, double* log_w,
                        double* mahalanobis2, std::size_t l) {
  LandmarkGaussian g;
  g.mean << lm.x[l], lm.y[l];
  g.cov << lm.sxx[l], lm.sxy[l], lm.sxy[l], lm.syy[l];
  const Pose p(pose.x[l], pose.y[l], pose.theta[l]);
  const LandmarkObservation terms = evaluate_observation(sensor, g, p, z, r);
  if (log_w != nullptr) log_w[l] += terms.log_likelihood;
  if (mahalanobis2 != nullptr) mahalanobis2[l] = terms.mahalanobis2;
  apply_update(g, terms, r);
  lm.x[l] = g.mean[0];
  lm.y[l] = g.mean[1];
  lm.sxx[l] = g.cov(0, 0);
  lm.sxy[l] = g.cov(0, 1);
  lm.syy[l] = g.cov(1, 1);
}

// Lanes [0, count) of the columns (already offset to the chunk); returns the flags of the lanes
// left unchanged for the scalar path in `fallback`.
template <bool kOffset, bool kWeight, bool kDistance>
void update_chunk(const SensorOffset& off, double yaw, double r00, double r01, double r11,
                  double z0, double z1, const double* __restrict px, const double* __restrict py,
                  const double* __restrict pt, double* __restrict lx, double* __restrict ly,
                  double* __restrict lxx, double* __restrict lxy, double* __restrict lyy,
                  double* __restrict log_w, double* __restrict mahalanobis2, std::size_t count,
                  double* __restrict fallback) {
  // Restrict-qualified parameters (not struct members): GCC then needs no alias checks.
  for (std::size_t l = 0; l < count; ++l) {
    const double mx = lx[l];
    const double my = ly[l];
    const double cxx = lxx[l];
    const double cxy = lxy[l];
    const double cyy = lyy[l];
    const LaneTerms t = lane_terms<kOffset>(off, yaw, r00, r01, r11, z0, z1, px[l], py[l], pt[l],
                                            mx, my, cxx, cxy, cyy);
    bool good = t.good;
    const double v0 = t.v0;
    const double v1 = t.v1;
    const double g00 = t.g00;
    const double g01 = t.g01;
    const double g10 = t.g10;
    const double g11 = t.g11;
    const double a00 = t.a00;
    const double a01 = t.a01;
    const double a10 = t.a10;
    const double a11 = t.a11;
    const double q00 = t.q00;
    const double q01 = t.q01;
    const double q11 = t.q11;
    const double det = q00 * q11 - q01 * q01;
    good = good & (det > 0.0) & (det < 1e300);
    const double inv_det = 1.0 / det;
    if constexpr (kWeight || kDistance) {
      const double quad = v0 * v0 * q11 - 2.0 * v0 * v1 * q01 + v1 * v1 * q00;
      if constexpr (kWeight) {
        const double ll =
            -kLogTwoPi - 0.5 * log_positive(select(good, det, 1.0)) - 0.5 * (quad * inv_det);
        log_w[l] = select(good, log_w[l] + ll, log_w[l]);
      }
      if constexpr (kDistance) mahalanobis2[l] = quad * inv_det;  // a fallback lane rewrites it
    }
    // K = Sigma G^T Q^-1 = (G Sigma)^T Q^-1.
    const double i00 = q11 * inv_det;
    const double i01 = -q01 * inv_det;
    const double i11 = q00 * inv_det;
    const double k00 = a00 * i00 + a10 * i01;
    const double k01 = a00 * i01 + a10 * i11;
    const double k10 = a01 * i00 + a11 * i01;
    const double k11 = a01 * i01 + a11 * i11;
    const double nx = mx + (k00 * v0 + k01 * v1);
    const double ny = my + (k10 * v0 + k11 * v1);
    // Joseph form: A Sigma A^T + K R K^T, A = I - K G.
    const double b00 = 1.0 - (k00 * g00 + k01 * g10);
    const double b01 = -(k00 * g01 + k01 * g11);
    const double b10 = -(k10 * g00 + k11 * g10);
    const double b11 = 1.0 - (k10 * g01 + k11 * g11);
    const double c00 = b00 * cxx + b01 * cxy;
    const double c01 = b00 * cxy + b01 * cyy;
    const double c10 = b10 * cxx + b11 * cxy;
    const double c11 = b10 * cxy + b11 * cyy;
    const double e00 = k00 * r00 + k01 * r01;
    const double e01 = k00 * r01 + k01 * r11;
    const double e10 = k10 * r00 + k11 * r01;
    const double e11 = k10 * r01 + k11 * r11;
    const double nxx = (c00 * b00 + c01 * b01) + (e00 * k00 + e01 * k01);
    const double nxy = 0.5 * (((c00 * b10 + c01 * b11) + (e00 * k10 + e01 * k11)) +
                              ((c10 * b00 + c11 * b01) + (e10 * k00 + e11 * k01)));
    const double nyy = (c10 * b10 + c11 * b11) + (e10 * k10 + e11 * k11);
    lx[l] = select(good, nx, mx);
    ly[l] = select(good, ny, my);
    lxx[l] = select(good, nxx, cxx);
    lxy[l] = select(good, nxy, cxy);
    lyy[l] = select(good, nyy, cyy);
    fallback[l] = select(good, 0.0, 1.0);
  }
}

}  // namespace

void update_landmark_lanes(const RangeBearingModel& sensor, const Eigen::Matrix2d& r,
                           const Eigen::Vector2d& z, PoseLanes pose, LandmarkLanes lm,
                           double* log_w, std::size_t lanes, double* mahalanobis2) {
  const SensorOffset& off = sensor.offset();
  const double yaw = wrap_angle(off.yaw);
  const double r00 = r(0, 0);
  const double r01 = 0.5 * (r(0, 1) + r(1, 0));
  const double r11 = r(1, 1);
  double fallback[kChunk];  // 1 for a lane left to the scalar path
  // The chunk loop for one combination of the three options, each a compile-time constant.
  const auto run = [&](auto offset, auto weight, auto distance) {
    for (std::size_t first = 0; first < lanes; first += kChunk) {
      const std::size_t count = std::min(kChunk, lanes - first);
      const PoseLanes p{pose.x + first, pose.y + first, pose.theta + first};
      const LandmarkLanes m{lm.x + first, lm.y + first, lm.sxx + first, lm.sxy + first,
                            lm.syy + first};
      double* w = decltype(weight)::value ? log_w + first : nullptr;
      double* d2 = decltype(distance)::value ? mahalanobis2 + first : nullptr;
      update_chunk<decltype(offset)::value, decltype(weight)::value, decltype(distance)::value>(
          off, yaw, r00, r01, r11, z[0], z[1], p.x, p.y, p.theta, m.x, m.y, m.sxx, m.sxy, m.syy, w,
          d2, count, fallback);
      for (std::size_t l = 0; l < count; ++l) {
        if (fallback[l] != 0.0) update_lane_scalar(sensor, r, z, p, m, w, d2, l);
      }
    }
  };
  const auto with_distance = [&](auto offset, auto weight) {
    if (mahalanobis2 != nullptr) {
      run(offset, weight, std::true_type{});
    } else {
      run(offset, weight, std::false_type{});
    }
  };
  const auto with_weight = [&](auto offset) {
    if (log_w != nullptr) {
      with_distance(offset, std::true_type{});
    } else {
      with_distance(offset, std::false_type{});
    }
  };
  if (off.x != 0.0 || off.y != 0.0) {
    with_weight(std::true_type{});
  } else {
    with_weight(std::false_type{});
  }
}

namespace {

// Lanes per pass of the proposal kernels: their inputs are copied into local arrays of this
// many lanes (GCC then sees that nothing aliases).
constexpr std::size_t kProposalChunk = 32;

template <int N>
constexpr int kEntries = N*(N + 1) / 2;

// Entry (i, j), i <= j, of the row-by-row upper triangle.
template <int N>
constexpr int upper(int i, int j) noexcept {
  return i * N - i * (i - 1) / 2 + (j - i);
}

template <int N>
PoseGaussian<N> proposal_of(const ProposalLanes<N>& p, std::size_t l) {
  PoseGaussian<N> g;
  for (int i = 0; i < N; ++i) {
    g.mean[i] = p.mean[i][l];
    for (int j = i; j < N; ++j) g.cov(i, j) = g.cov(j, i) = p.cov[upper<N>(i, j)][l];
  }
  return g;
}

template <int N>
void store_proposal(const PoseGaussian<N>& g, const ProposalLanes<N>& p, std::size_t l) {
  for (int i = 0; i < N; ++i) {
    p.mean[i][l] = g.mean[i];
    for (int j = i; j < N; ++j) p.cov[upper<N>(i, j)][l] = g.cov(i, j);
  }
}

// The proposal lanes [first, first + count) copied into local arrays, folded, written back.
// kScaled: the weight term under L + (weight_scale - 1) R (proposal.h weight_scale).
template <int N, bool kOffset, bool kScaled>
void fold_chunk(const RangeBearingModel& sensor, const Eigen::Matrix2d& r, const Eigen::Vector2d& z,
                const ProposalLanes<N>& p, const ConstLandmarkLanes& lm, double* log_w,
                std::size_t first, std::size_t count, double weight_scale) {
  constexpr int E = kEntries<N>;
  constexpr std::size_t C = kProposalChunk;
  const SensorOffset& off = sensor.offset();
  const double yaw = wrap_angle(off.yaw);
  const double r00 = r(0, 0);
  const double r01 = 0.5 * (r(0, 1) + r(1, 0));
  const double r11 = r(1, 1);
  const double w00 = (weight_scale - 1.0) * r00;
  const double w01 = (weight_scale - 1.0) * r01;
  const double w11 = (weight_scale - 1.0) * r11;
  const double z0 = z[0];
  const double z1 = z[1];
  alignas(64) double mean[N][C];
  alignas(64) double cov[E][C];
  alignas(64) double land[5][C];
  alignas(64) double weight[C];
  alignas(64) double fallback[C];
  const double* const land_col[5] = {lm.x, lm.y, lm.sxx, lm.sxy, lm.syy};
  for (int k = 0; k < N; ++k) std::copy_n(p.mean[k] + first, count, mean[k]);
  for (int e = 0; e < E; ++e) std::copy_n(p.cov[e] + first, count, cov[e]);
  for (int k = 0; k < 5; ++k) std::copy_n(land_col[k] + first, count, land[k]);
  std::copy_n(log_w + first, count, weight);
  for (std::size_t l = 0; l < count; ++l) {
    double pc[N][N];
    double m[N];
#pragma GCC unroll 5
    for (int i = 0; i < N; ++i) {
      m[i] = mean[i][l];
#pragma GCC unroll 5
      for (int j = i; j < N; ++j) pc[i][j] = pc[j][i] = cov[upper<N>(i, j)][l];
    }
    const double th = m[2];
    const double cxx = land[2][l];
    const double cxy = land[3][l];
    const double cyy = land[4][l];
    const LaneTerms t = lane_terms<kOffset>(off, yaw, r00, r01, r11, z0, z1, m[0], m[1], th,
                                            land[0][l], land[1][l], cxx, cxy, cyy);
    const double sx = t.sx;
    const double sy = t.sy;
    const double dx = t.dx;
    const double dy = t.dy;
    const double inv_q = t.inv_q;
    const double inv_r = t.inv_r;
    // d(d)/d(theta) = (p_y - y, -(p_x - x)); zero without an offset.
    const double ex = sy - m[1];
    const double ey = m[0] - sx;
    bool good = t.good;
    const double v0 = t.v0;
    const double v1 = t.v1;
    const double q00 = t.q00;
    const double q01 = t.q01;
    const double q11 = t.q11;
    // G_s: three nonzero columns.
    const double s00 = -dx * inv_r;
    const double s01 = -dy * inv_r;
    const double s02 = (dx * ex + dy * ey) * inv_r;
    const double s10 = dy * inv_q;
    const double s11 = -dx * inv_q;
    const double s12 = (dx * ey - dy * ex) * inv_q - 1.0;
    // gp = G_s Sigma_s (2 x N); Sigma_s G_s^T is its transpose.
    double gp0[N];
    double gp1[N];
#pragma GCC unroll 5
    for (int j = 0; j < N; ++j) {
      gp0[j] = s00 * pc[0][j] + s01 * pc[1][j] + s02 * pc[2][j];
      gp1[j] = s10 * pc[0][j] + s11 * pc[1][j] + s12 * pc[2][j];
    }
    // L = G_s Sigma_s G_s^T + Q, its inverse and log-determinant.
    const double l00 = gp0[0] * s00 + gp0[1] * s01 + gp0[2] * s02 + q00;
    const double l01 = 0.5 * ((gp0[0] * s10 + gp0[1] * s11 + gp0[2] * s12 + q01) +
                              (gp1[0] * s00 + gp1[1] * s01 + gp1[2] * s02 + q01));
    const double l11 = gp1[0] * s10 + gp1[1] * s11 + gp1[2] * s12 + q11;
    const double det = l00 * l11 - l01 * l01;
    good = good & (det > 0.0) & (det < 1e300);
    const double inv_det = 1.0 / det;
    const double i00 = l11 * inv_det;
    const double i01 = -l01 * inv_det;
    const double i11 = l00 * inv_det;
    const double m2 = v0 * (i00 * v0 + i01 * v1) + v1 * (i01 * v0 + i11 * v1);
    double ll = -kLogTwoPi - 0.5 * log_positive(select(good, det, 1.0)) - 0.5 * m2;
    if constexpr (kScaled) {
      const double a00 = l00 + w00;
      const double a01 = l01 + w01;
      const double a11 = l11 + w11;
      const double det_w = a00 * a11 - a01 * a01;
      good = good & (det_w > 0.0) & (det_w < 1e300);
      const double m2_w = (v0 * (a11 * v0 - a01 * v1) + v1 * (a00 * v1 - a01 * v0)) / det_w;
      ll = -kLogTwoPi - 0.5 * log_positive(select(good, det_w, 1.0)) - 0.5 * m2_w;
    }
    // K = Sigma_s G_s^T L^-1 (N x 2); the folded mean; A = I - K G_s.
    double k0[N];
    double k1[N];
    double nm[N];
#pragma GCC unroll 5
    for (int i = 0; i < N; ++i) {
      k0[i] = gp0[i] * i00 + gp1[i] * i01;
      k1[i] = gp0[i] * i01 + gp1[i] * i11;
      nm[i] = m[i] + (k0[i] * v0 + k1[i] * v1);
    }
    nm[2] = wrap_step(wrap_step(nm[2]));
    good = good & (nm[2] > -kPi) & (nm[2] <= kPi);
    double a[N][N];
#pragma GCC unroll 5
    for (int i = 0; i < N; ++i) {
#pragma GCC unroll 5
      for (int j = 0; j < N; ++j) {
        const double kg = j < 3 ? k0[i] * (j == 0   ? s00
                                           : j == 1 ? s01
                                                    : s02) +
                                      k1[i] * (j == 0   ? s10
                                               : j == 1 ? s11
                                                        : s12)
                                : 0.0;
        a[i][j] = (i == j ? 1.0 : 0.0) - kg;
      }
    }
    // A Sigma_s A^T + K Q K^T (Joseph form), symmetrised.
    double ap[N][N];
#pragma GCC unroll 5
    for (int i = 0; i < N; ++i) {
#pragma GCC unroll 5
      for (int j = 0; j < N; ++j) {
        double sum = 0.0;
#pragma GCC unroll 5
        for (int k = 0; k < N; ++k) sum = sum + a[i][k] * pc[k][j];
        ap[i][j] = sum;
      }
    }
    double kq0[N];
    double kq1[N];
#pragma GCC unroll 5
    for (int i = 0; i < N; ++i) {
      kq0[i] = k0[i] * q00 + k1[i] * q01;
      kq1[i] = k0[i] * q01 + k1[i] * q11;
    }
    double nc[N][N];
#pragma GCC unroll 5
    for (int i = 0; i < N; ++i) {
#pragma GCC unroll 5
      for (int j = 0; j < N; ++j) {
        double sum = 0.0;
#pragma GCC unroll 5
        for (int k = 0; k < N; ++k) sum = sum + ap[i][k] * a[j][k];
        nc[i][j] = sum + (kq0[i] * k0[j] + kq1[i] * k1[j]);
      }
    }
#pragma GCC unroll 5
    for (int i = 0; i < N; ++i) {
      mean[i][l] = select(good, nm[i], m[i]);
#pragma GCC unroll 5
      for (int j = i; j < N; ++j) {
        const double sym = 0.5 * (nc[i][j] + nc[j][i]);
        cov[upper<N>(i, j)][l] = select(good, sym, pc[i][j]);
      }
    }
    weight[l] = select(good, weight[l] + ll, weight[l]);
    fallback[l] = select(good, 0.0, 1.0);
  }
  for (int k = 0; k < N; ++k) std::copy_n(mean[k], count, p.mean[k] + first);
  for (int e = 0; e < E; ++e) std::copy_n(cov[e], count, p.cov[e] + first);
  std::copy_n(weight, count, log_w + first);
  for (std::size_t l = 0; l < count; ++l) {
    if (fallback[l] == 0.0) continue;
    const std::size_t at = first + l;
    LandmarkGaussian g;
    g.mean << lm.x[at], lm.y[at];
    g.cov << lm.sxx[at], lm.sxy[at], lm.sxy[at], lm.syy[at];
    const PoseGaussian<N> before = proposal_of<N>(p, at);
    ProposalObservation<N> terms = evaluate_proposal<N>(sensor, g, before, z, r);
    if constexpr (kScaled) scale_weight<N>(terms, r, weight_scale);
    log_w[at] += terms.log_likelihood;
    store_proposal<N>(fold<N>(before, terms), p, at);
  }
}

}  // namespace

template <int N>
void fold_proposal_lanes(const RangeBearingModel& sensor, const Eigen::Matrix2d& r,
                         const Eigen::Vector2d& z, ProposalLanes<N> proposal, ConstLandmarkLanes lm,
                         double* log_w, std::size_t lanes, double weight_scale) {
  const bool has_offset = sensor.offset().x != 0.0 || sensor.offset().y != 0.0;
  const bool scaled = weight_scale != 1.0;
  for (std::size_t first = 0; first < lanes; first += kProposalChunk) {
    const std::size_t count = std::min(kProposalChunk, lanes - first);
    if (has_offset) {
      if (scaled) {
        fold_chunk<N, true, true>(sensor, r, z, proposal, lm, log_w, first, count, weight_scale);
      } else {
        fold_chunk<N, true, false>(sensor, r, z, proposal, lm, log_w, first, count, 1.0);
      }
    } else if (scaled) {
      fold_chunk<N, false, true>(sensor, r, z, proposal, lm, log_w, first, count, weight_scale);
    } else {
      fold_chunk<N, false, false>(sensor, r, z, proposal, lm, log_w, first, count, 1.0);
    }
  }
}

template <int N>
void sample_pose_lanes(ProposalLanes<N> proposal, const double* normals, double* const* state,
                       std::size_t lanes) {
  constexpr int E = kEntries<N>;
  constexpr std::size_t C = kProposalChunk;
  constexpr double kEpsilon = 2.220446049250313e-16;
  for (std::size_t first = 0; first < lanes; first += C) {
    const std::size_t count = std::min(C, lanes - first);
    alignas(64) double mean[N][C];
    alignas(64) double cov[E][C];
    alignas(64) double draw[N][C];
    alignas(64) double out[N][C];
    alignas(64) double fallback[C];
    for (int k = 0; k < N; ++k) std::copy_n(proposal.mean[k] + first, count, mean[k]);
    for (int e = 0; e < E; ++e) std::copy_n(proposal.cov[e] + first, count, cov[e]);
    for (int k = 0; k < N; ++k) {
      for (std::size_t l = 0; l < count; ++l) draw[k][l] = normals[N * (first + l) + k];
    }
    for (std::size_t l = 0; l < count; ++l) {
      // psd_factor: Cholesky with pivots at or below the threshold giving zero columns.
      double pc[N][N];
#pragma GCC unroll 5
      for (int i = 0; i < N; ++i) {
#pragma GCC unroll 5
        for (int j = i; j < N; ++j) pc[i][j] = pc[j][i] = cov[upper<N>(i, j)][l];
      }
      double scale = std::fabs(pc[0][0]);
#pragma GCC unroll 5
      for (int j = 1; j < N; ++j) {
        scale = select(std::fabs(pc[j][j]) > scale, std::fabs(pc[j][j]), scale);
      }
      const double threshold = 64.0 * N * kEpsilon * scale;
      double f[N][N] = {};
#pragma GCC unroll 5
      for (int j = 0; j < N; ++j) {
        double d = pc[j][j];
#pragma GCC unroll 5
        for (int k = 0; k < j; ++k) d = d - f[j][k] * f[j][k];
        const bool pivot = d > threshold;
        const double root = std::sqrt(select(pivot, d, 1.0));
        f[j][j] = select(pivot, root, 0.0);
#pragma GCC unroll 5
        for (int i = j + 1; i < N; ++i) {
          double e = pc[i][j];
#pragma GCC unroll 5
          for (int k = 0; k < j; ++k) e = e - f[i][k] * f[j][k];
          f[i][j] = select(pivot, e / root, 0.0);
        }
      }
      bool good = true;
#pragma GCC unroll 5
      for (int i = 0; i < N; ++i) {
        double sum = 0.0;
#pragma GCC unroll 5
        for (int j = 0; j <= i; ++j) sum = sum + f[i][j] * draw[j][l];
        out[i][l] = mean[i][l] + sum;
      }
      out[2][l] = wrap_step(wrap_step(out[2][l]));
      good = good & (out[2][l] > -kPi) & (out[2][l] <= kPi);
      fallback[l] = select(good, 0.0, 1.0);
    }
    for (std::size_t l = 0; l < count; ++l) {
      if (fallback[l] != 0.0) {
        const auto s =
            sample_pose<N>(proposal_of<N>(proposal, first + l), &normals[N * (first + l)]);
        for (int k = 0; k < N; ++k) out[k][l] = s[k];
      }
      for (int k = 0; k < N; ++k) state[k][first + l] = out[k][l];
    }
  }
}

template void fold_proposal_lanes<3>(const RangeBearingModel&, const Eigen::Matrix2d&,
                                     const Eigen::Vector2d&, ProposalLanes<3>, ConstLandmarkLanes,
                                     double*, std::size_t, double);
template void fold_proposal_lanes<5>(const RangeBearingModel&, const Eigen::Matrix2d&,
                                     const Eigen::Vector2d&, ProposalLanes<5>, ConstLandmarkLanes,
                                     double*, std::size_t, double);
template void sample_pose_lanes<3>(ProposalLanes<3>, const double*, double* const*, std::size_t);
template void sample_pose_lanes<5>(ProposalLanes<5>, const double*, double* const*, std::size_t);

}  // namespace fastslam::engine
