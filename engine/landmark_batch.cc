#include "engine/landmark_batch.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>

#include "engine/angles.h"
#include "engine/landmark_ekf.h"
#include "parallel/internal/vmath.h"

namespace fastslam::engine {
namespace {

using parallel::internal::arctan2;
using parallel::internal::log_positive;
using parallel::internal::select;

// Lanes per pass of the vector loop: bounds the stack flags of the lanes that fall back.
constexpr std::size_t kChunk = 64;

// One exact step of wrap_angle for a within one turn of (-pi, pi]: a select between constants,
// the subtraction unconditional (a - 0 == a), so the loop if-converts.
[[gnu::always_inline]] inline double wrap_step(double a) noexcept {
  const double shift = select(a > kPi, kTwoPi, 0.0) - select(a <= -kPi, kTwoPi, 0.0);
  return a - shift;
}

// The scalar EKF of engine/landmark_ekf.h for one lane.
void update_lane_scalar(const RangeBearingModel& sensor, const Eigen::Matrix2d& r,
                        const Eigen::Vector2d& z, PoseLanes pose, LandmarkLanes lm, double* log_w,
                        std::size_t l) {
  LandmarkGaussian g;
  g.mean << lm.x[l], lm.y[l];
  g.cov << lm.sxx[l], lm.sxy[l], lm.sxy[l], lm.syy[l];
  const Pose p(pose.x[l], pose.y[l], pose.theta[l]);
  const LandmarkObservation terms = evaluate_observation(sensor, g, p, z, r);
  if (log_w != nullptr) log_w[l] += terms.log_likelihood;
  apply_update(g, terms, r);
  lm.x[l] = g.mean[0];
  lm.y[l] = g.mean[1];
  lm.sxx[l] = g.cov(0, 0);
  lm.sxy[l] = g.cov(0, 1);
  lm.syy[l] = g.cov(1, 1);
}

// Lanes [0, count) of the columns (already offset to the chunk); returns the flags of the lanes
// left unchanged for the scalar path in `fallback`.
template <bool kOffset, bool kWeight>
void update_chunk(const SensorOffset& off, double yaw, double r00, double r01, double r11,
                  double z0, double z1, const double* __restrict px, const double* __restrict py,
                  const double* __restrict pt, double* __restrict lx, double* __restrict ly,
                  double* __restrict lxx, double* __restrict lxy, double* __restrict lyy,
                  double* __restrict log_w, std::size_t count, double* __restrict fallback) {
  // Restrict-qualified parameters (not struct members): GCC then needs no alias checks.
  for (std::size_t l = 0; l < count; ++l) {
    const double th = pt[l];
    double sx = px[l];
    double sy = py[l];
    bool good = std::fabs(th) <= kPi;
    if constexpr (kOffset) {
      double c = 0.0;
      double s = 0.0;
      parallel::internal::sincos(th, c, s);
      sx = sx + (off.x * c - off.y * s);
      sy = sy + (off.x * s + off.y * c);
    }
    const double mx = lx[l];
    const double my = ly[l];
    const double cxx = lxx[l];
    const double cxy = lxy[l];
    const double cyy = lyy[l];
    const double dx = mx - sx;
    const double dy = my - sy;
    const double q = dx * dx + dy * dy;
    const double range = std::sqrt(q);
    const double inv_q = 1.0 / q;
    const double inv_r = range * inv_q;
    // Bearing in [-pi, pi] minus a heading and a yaw in (-pi, pi]: two exact steps wrap it.
    const double bearing = wrap_step(wrap_step(arctan2(dy, dx) - th - yaw));
    const double v0 = z0 - range;
    const double v1 = wrap_step(z1 - bearing);
    good = good & (q > 0.0) & (q < 1e300) & (v1 > -kPi) & (v1 <= kPi);
    // G_mu, then G Sigma, Q = G Sigma G^T + R (symmetrised as evaluate_observation does).
    const double g00 = dx * inv_r;
    const double g01 = dy * inv_r;
    const double g10 = -dy * inv_q;
    const double g11 = dx * inv_q;
    const double a00 = g00 * cxx + g01 * cxy;
    const double a01 = g00 * cxy + g01 * cyy;
    const double a10 = g10 * cxx + g11 * cxy;
    const double a11 = g10 * cxy + g11 * cyy;
    const double q00 = a00 * g00 + a01 * g01 + r00;
    const double q01 = 0.5 * ((a00 * g10 + a01 * g11 + r01) + (a10 * g00 + a11 * g01 + r01));
    const double q11 = a10 * g10 + a11 * g11 + r11;
    const double det = q00 * q11 - q01 * q01;
    good = good & (det > 0.0) & (det < 1e300);
    const double inv_det = 1.0 / det;
    if constexpr (kWeight) {
      const double quad = v0 * v0 * q11 - 2.0 * v0 * v1 * q01 + v1 * v1 * q00;
      const double ll =
          -kLogTwoPi - 0.5 * log_positive(select(good, det, 1.0)) - 0.5 * (quad * inv_det);
      log_w[l] = select(good, log_w[l] + ll, log_w[l]);
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
                           double* log_w, std::size_t lanes) {
  const SensorOffset& off = sensor.offset();
  const bool has_offset = off.x != 0.0 || off.y != 0.0;
  const double yaw = wrap_angle(off.yaw);
  const double r00 = r(0, 0);
  const double r01 = 0.5 * (r(0, 1) + r(1, 0));
  const double r11 = r(1, 1);
  double fallback[kChunk];  // 1 for a lane left to the scalar path
  for (std::size_t first = 0; first < lanes; first += kChunk) {
    const std::size_t count = std::min(kChunk, lanes - first);
    const PoseLanes p{pose.x + first, pose.y + first, pose.theta + first};
    const LandmarkLanes m{lm.x + first, lm.y + first, lm.sxx + first, lm.sxy + first,
                          lm.syy + first};
    double* w = log_w == nullptr ? nullptr : log_w + first;
    if (has_offset) {
      if (w != nullptr) {
        update_chunk<true, true>(off, yaw, r00, r01, r11, z[0], z[1], p.x, p.y, p.theta, m.x, m.y,
                                 m.sxx, m.sxy, m.syy, w, count, fallback);
      } else {
        update_chunk<true, false>(off, yaw, r00, r01, r11, z[0], z[1], p.x, p.y, p.theta, m.x, m.y,
                                  m.sxx, m.sxy, m.syy, w, count, fallback);
      }
    } else if (w != nullptr) {
      update_chunk<false, true>(off, yaw, r00, r01, r11, z[0], z[1], p.x, p.y, p.theta, m.x, m.y,
                                m.sxx, m.sxy, m.syy, w, count, fallback);
    } else {
      update_chunk<false, false>(off, yaw, r00, r01, r11, z[0], z[1], p.x, p.y, p.theta, m.x, m.y,
                                 m.sxx, m.sxy, m.syy, w, count, fallback);
    }
    for (std::size_t l = 0; l < count; ++l) {
      if (fallback[l] != 0.0) update_lane_scalar(sensor, r, z, p, m, w, l);
    }
  }
}

}  // namespace fastslam::engine
