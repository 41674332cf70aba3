// The motion models of engine/motion_model.h over a block of particles at once, in
// structure-of-arrays columns, so the compiler vectorises across particles: sample_block (the
// FastSLAM 1.0 draw) and predict_block (the FastSLAM 2.0 prior, mean and covariance), each
// carrying a block through every queued control step in one call. Each equals the scalar model
// up to rounding (vmath's sines; tests bound it by 1e-12), and a lane's bits depend on its own
// inputs alone, whatever the block size or position (see docs/engine-config.md for how). Blocks
// are padded to kMotionLanes; `StateBlock`/`CovBlock` borrow non-overlapping columns. Adding a
// model means adding its `Lane` below. Pure functions: concurrent calls on disjoint blocks are
// safe. Costs: O(lanes x steps), no allocation (up to 20 KB of stack arrays).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <span>
#include <utility>

#include <Eigen/Core>

#include "engine/angles.h"
#include "engine/motion_model.h"
#include "parallel/vector_math.h"

namespace fastslam::engine {

// Lanes processed together; blocks are padded to a multiple of it. Eight doubles are one
// AVX-512 register and one 64-byte cache line.
inline constexpr std::size_t kMotionLanes = 8;

// Round `count` up to whole groups of kMotionLanes.
constexpr std::size_t padded_lanes(std::size_t count) noexcept {
  return (count + kMotionLanes - 1) / kMotionLanes * kMotionLanes;
}

template <int N>
struct StateBlock {
  std::array<double*, N> col{};
  std::size_t lanes = 0;  // a multiple of kMotionLanes
};

template <int N>
inline constexpr int kCovEntries = N*(N + 1) / 2;

// Index of entry (r, c), r <= c, of the row-by-row upper triangle of an N x N matrix.
template <int N>
constexpr int upper_index(int r, int c) noexcept {
  return r * N - r * (r - 1) / 2 + (c - r);
}

template <int N>
using CovBlock = std::array<double*, kCovEntries<N>>;

namespace motion_batch_internal {

using parallel::madd;
using parallel::sincos_in_domain;

// wrap_angle(a) for a within one turn of (-pi, pi] (the sum of a wrapped heading and a step of
// less than 2 pi), with the same result bits; `ok` turns false when a is beyond that (the lane
// then takes the scalar path, whose wrap_angle handles any angle).
[[gnu::always_inline]] inline double wrap_near(double a, bool& ok) noexcept {
  // The shift is a select between constants and the subtraction unconditional, so that the
  // loop if-converts without masked stores (AVX2 too): a - 0 == a, a - (-2 pi) == a + 2 pi.
  const double shift = (a > kPi ? kTwoPi : 0.0) - (a <= -kPi ? kTwoPi : 0.0);
  const double r = a - shift;
  ok = ok & (r > -kPi) & (r <= kPi);
  return r;
}

// Whether sincos_small(u1) is sincos(u1): steering angles are well inside it (the car's limit
// is far below pi/4); a lane beyond it takes the scalar path.
[[gnu::always_inline]] inline bool steer_in_small_domain(double u1) noexcept {
  return std::fabs(u1) <= parallel::kSinCosSmallArg;
}

// The Jacobian dh/ds of a model is the identity plus the entries listed in kJacobianPattern
// (row, column); `terms` computes their values and V = dh/du at (s, u), and `move` applies the
// motion h(u, s) to one lane in place, returning false when the lane needs the scalar path.
template <class Model>
struct Lane;

template <>
struct Lane<BaileyCarModel> {
  static constexpr int kN = 3;
  static constexpr std::array<std::array<int, 2>, 2> kJacobianPattern = {{{0, 2}, {1, 2}}};

  [[gnu::always_inline]] static bool move(const BaileyCarModel& m, double (&s)[kN], double u0,
                                          double u1, double dt) noexcept {
    const double vdt = u0 * dt;
    const double heading = u1 + s[2];
    double c, sn, cg, sg;
    parallel::sincos(heading, c, sn);
    parallel::sincos_small(u1, cg, sg);  // a steering angle: no range reduction
    bool ok = sincos_in_domain(heading) & steer_in_small_domain(u1);
    s[0] = madd(vdt, c, s[0]);
    s[1] = madd(vdt, sn, s[1]);
    s[2] = wrap_near(madd(vdt * sg, 1.0 / m.wheelbase(), s[2]), ok);  // hoisted reciprocal
    return ok;
  }

  [[gnu::always_inline]] static void terms(const BaileyCarModel& m, const double (&s)[kN],
                                           double u0, double u1, double dt, double (&j)[2],
                                           double (&v)[kN][2]) noexcept {
    const double vdt = u0 * dt;
    double c, sn, cg, sg;
    parallel::sincos(u1 + s[2], c, sn);
    parallel::sincos_small(u1, cg, sg);  // lanes beyond its domain: move() is false
    j[0] = -(vdt * sn);
    j[1] = vdt * c;
    v[0][0] = dt * c;
    v[0][1] = -(vdt * sn);
    v[1][0] = dt * sn;
    v[1][1] = vdt * c;
    v[2][0] = dt * sg / m.wheelbase();
    v[2][1] = vdt * cg / m.wheelbase();
  }
};

template <>
struct Lane<UnicycleModel> {
  static constexpr int kN = 3;
  static constexpr std::array<std::array<int, 2>, 2> kJacobianPattern = {{{0, 2}, {1, 2}}};

  [[gnu::always_inline]] static bool move(const UnicycleModel& /*m*/, double (&s)[kN], double u0,
                                          double u1, double dt) noexcept {
    const double vdt = u0 * dt;
    double c, sn;
    parallel::sincos(s[2], c, sn);
    bool ok = sincos_in_domain(s[2]);
    s[0] = madd(vdt, c, s[0]);
    s[1] = madd(vdt, sn, s[1]);
    s[2] = wrap_near(madd(u1, dt, s[2]), ok);
    return ok;
  }

  [[gnu::always_inline]] static void terms(const UnicycleModel& /*m*/, const double (&s)[kN],
                                           double u0, double /*u1*/, double dt, double (&j)[2],
                                           double (&v)[kN][2]) noexcept {
    const double vdt = u0 * dt;
    double c, sn;
    parallel::sincos(s[2], c, sn);
    j[0] = -(vdt * sn);
    j[1] = vdt * c;
    v[0][0] = dt * c;
    v[0][1] = 0.0;
    v[1][0] = dt * sn;
    v[1][1] = 0.0;
    v[2][0] = 0.0;
    v[2][1] = dt;
  }
};

template <>
struct Lane<AckermannModel> {
  static constexpr int kN = 3;
  static constexpr std::array<std::array<int, 2>, 2> kJacobianPattern = {{{0, 2}, {1, 2}}};

  [[gnu::always_inline]] static bool move(const AckermannModel& m, double (&s)[kN], double u0,
                                          double u1, double dt) noexcept {
    const AckermannGeometry& g = m.geometry();
    double ca, sa, c, sn;
    parallel::sincos(u1, ca, sa);
    parallel::sincos(s[2], c, sn);
    bool ok = sincos_in_domain(u1) & sincos_in_domain(s[2]);
    const double t = sa / ca;
    const double vc = u0 / (1.0 - t * g.h / g.l);
    const double k = vc * t / g.l;
    const double ex = madd(g.a, sn, g.b * c);     // a sin(phi) + b cos(phi)
    const double ey = madd(g.a, c, -(g.b * sn));  // a cos(phi) - b sin(phi)
    s[0] = madd(dt, madd(vc, c, -(k * ex)), s[0]);
    s[1] = madd(dt, madd(vc, sn, k * ey), s[1]);
    s[2] = wrap_near(madd(dt, k, s[2]), ok);
    return ok;
  }

  [[gnu::always_inline]] static void terms(const AckermannModel& m, const double (&s)[kN],
                                           double u0, double u1, double dt, double (&j)[2],
                                           double (&v)[kN][2]) noexcept {
    const AckermannGeometry& g = m.geometry();
    double ca, sa, c, sn;
    parallel::sincos(u1, ca, sa);
    parallel::sincos(s[2], c, sn);
    const double t = sa / ca;
    const double sec2 = madd(t, t, 1.0);
    const double denom = 1.0 - t * g.h / g.l;
    const double vc = u0 / denom;
    const double k = vc * t / g.l;
    const double dvc_dve = 1.0 / denom;
    const double dvc_dal = u0 * (g.h / g.l) * sec2 / (denom * denom);
    const double dk_dve = dvc_dve * t / g.l;
    const double dk_dal = madd(dvc_dal, t, vc * sec2) / g.l;
    const double ex = madd(g.a, sn, g.b * c);
    const double ey = madd(g.a, c, -(g.b * sn));
    j[0] = dt * madd(-vc, sn, -(k * ey));
    j[1] = dt * madd(vc, c, -(k * ex));
    v[0][0] = dt * madd(dvc_dve, c, -(dk_dve * ex));
    v[0][1] = dt * madd(dvc_dal, c, -(dk_dal * ex));
    v[1][0] = dt * madd(dvc_dve, sn, dk_dve * ey);
    v[1][1] = dt * madd(dvc_dal, sn, dk_dal * ey);
    v[2][0] = dt * dk_dve;
    v[2][1] = dt * dk_dal;
  }
};

// Both no-odometry models. The curvature walk's heading step v' kappa' dt adds the entries
// (2, 3) and (2, 4) = (kappa' dt, v' dt) to J, where the turn-rate walk has (2, 4) = dt only.
template <class Turn>
struct Lane<BrownianModel<Turn>> {
  using Model = BrownianModel<Turn>;
  static constexpr int kN = 5;
  static constexpr auto kJacobianPattern = [] {
    if constexpr (Turn::kRateDependsOnSpeed) {
      return std::array<std::array<int, 2>, 6>{{{0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}, {2, 4}}};
    } else {
      return std::array<std::array<int, 2>, 5>{{{0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 4}}};
    }
  }();

  [[gnu::always_inline]] static bool move(const Model& /*m*/, double (&s)[kN], double u0, double u1,
                                          double dt) noexcept {
    const double v = s[3] + u0;
    const double w = s[4] + u1;
    double c, sn;
    parallel::sincos(s[2], c, sn);
    bool ok = sincos_in_domain(s[2]);
    s[0] = madd(v * c, dt, s[0]);
    s[1] = madd(v * sn, dt, s[1]);
    s[2] = wrap_near(madd(Turn::rate(v, w), dt, s[2]), ok);
    s[3] = v;
    s[4] = w;
    return ok;
  }

  [[gnu::always_inline]] static void terms(const Model& /*m*/, const double (&s)[kN], double u0,
                                           double u1, double dt,
                                           double (&j)[kJacobianPattern.size()],
                                           double (&v)[kN][2]) noexcept {
    const double vel = s[3] + u0;
    double c, sn;
    parallel::sincos(s[2], c, sn);
    j[0] = -(vel * sn) * dt;
    j[1] = c * dt;
    j[2] = vel * c * dt;
    j[3] = sn * dt;
    if constexpr (Turn::kRateDependsOnSpeed) {
      j[4] = (s[4] + u1) * dt;
      j[5] = vel * dt;
    } else {
      j[4] = dt;
    }
#pragma GCC unroll 8
    for (auto& row : v) row[0] = row[1] = 0.0;
    v[0][0] = c * dt;
    v[1][0] = sn * dt;
    if constexpr (Turn::kRateDependsOnSpeed) {
      v[2][0] = j[4];  // kappa' dt
      v[2][1] = j[5];  // v' dt
    } else {
      v[2][1] = dt;
    }
    v[3][0] = 1.0;
    v[4][1] = 1.0;
  }
};

// P <- J P J^T + V M V^T on one lane's upper triangle `p`, J = I + the pattern entries `j`,
// M = diag(m0, m1). Only the upper triangle is computed, so the result is symmetric by
// construction.
template <class L, int N>
[[gnu::always_inline]] inline void propagate(double (&p)[kCovEntries<N>],
                                             const double (&j)[L::kJacobianPattern.size()],
                                             const double (&v)[N][2], double m0,
                                             double m1) noexcept {
  constexpr auto& pattern = L::kJacobianPattern;
  constexpr std::size_t kTerms = pattern.size();
  auto at = [&](int r, int c) -> double {
    return r <= c ? p[upper_index<N>(r, c)] : p[upper_index<N>(c, r)];
  };
  // JP = P + sum_e j_e e_{row_e} P_{col_e, :}: a full N x N matrix.
  double jp[N][N];
#pragma GCC unroll 8
  for (int r = 0; r < N; ++r) {
#pragma GCC unroll 8
    for (int c = 0; c < N; ++c) jp[r][c] = at(r, c);
  }
#pragma GCC unroll 8
  for (std::size_t e = 0; e < kTerms; ++e) {
    const int row = pattern[e][0];
    const int col = pattern[e][1];
#pragma GCC unroll 8
    for (int c = 0; c < N; ++c) jp[row][c] = madd(j[e], at(col, c), jp[row][c]);
  }
  // (JP) J^T = JP + sum_e j_e (JP)_{:, col_e} e_{row_e}^T, upper triangle, plus V M V^T.
#pragma GCC unroll 8
  for (int r = 0; r < N; ++r) {
#pragma GCC unroll 8
    for (int c = r; c < N; ++c) {
      double q = jp[r][c];
#pragma GCC unroll 8
      for (std::size_t e = 0; e < kTerms; ++e) {
        if (pattern[e][0] == c) q = madd(j[e], jp[r][pattern[e][1]], q);
      }
      q = madd(m0 * v[r][0], v[c][0], q);
      q = madd(m1 * v[r][1], v[c][1], q);
      p[upper_index<N>(r, c)] = q;
    }
  }
}

}  // namespace motion_batch_internal

// One control step: the control (u0, u1) applied for dt seconds.
struct ControlStep {
  double u0 = 0.0;
  double u1 = 0.0;
  double dt = 0.0;
};

namespace motion_batch_internal {

// Lanes per pass of the drivers below: the state of up to kChunk lanes is loaded into local
// arrays once, carried through every step (a vectorised loop per step, over local arrays, so
// there is no aliasing for the vectoriser to guard against; its trip count is a multiple of
// kMotionLanes, so no lane goes through a scalar remainder loop), and stored once.
inline constexpr std::size_t kChunk = 64;

}  // namespace motion_batch_internal

// For each step k in order, every lane l: s <- model.sample(s, u_k, dt_k, sigmas,
// {n0_k[l], n1_k[l]}), i.e. the motion under the control u_k + sigmas .* (n0_k[l], n1_k[l]),
// where n0_k = normals + 2 k block.lanes and n1_k = n0_k + block.lanes.
// REQUIRES: block.lanes % kMotionLanes == 0; normals holds 2 * steps.size() * block.lanes values.
template <class Model>
void sample_block(const Model& model, const StateBlock<Model::kStateDim>& block,
                  std::span<const ControlStep> steps, const typename Model::Control& sigmas,
                  const double* normals) noexcept {
  using L = motion_batch_internal::Lane<Model>;
  using motion_batch_internal::kChunk;
  using motion_batch_internal::madd;
  constexpr int N = Model::kStateDim;
  using Rows = double[N][kChunk];
  const double sigma0 = sigmas[0], sigma1 = sigmas[1];
  const std::size_t lanes = block.lanes;
  for (std::size_t first = 0; first < lanes; first += kChunk) {
    const std::size_t n = std::min(kChunk, lanes - first);
    // Two distinct arrays, the step alternating between them (a step needs its inputs intact
    // for the scalar fallback): the vectoriser sees that input and output never alias.
    alignas(64) Rows even;
    alignas(64) Rows odd;
    alignas(64) std::int64_t bad[kChunk];
#pragma GCC unroll 8
    for (int k = 0; k < N; ++k) {
      for (std::size_t l = 0; l < n; ++l) even[k][l] = block.col[k][first + l];
    }
    auto step_once = [&](const Rows& in, Rows& out, std::size_t step)
        __attribute__((always_inline)) {
      const ControlStep c = steps[step];
      const double* n0 = normals + 2 * step * lanes + first;
      const double* n1 = n0 + lanes;
      for (std::size_t l = 0; l < n; ++l) {
        double s[N];
#pragma GCC unroll 8
        for (int k = 0; k < N; ++k) s[k] = in[k][l];
        const bool ok =
            L::move(model, s, madd(sigma0, n0[l], c.u0), madd(sigma1, n1[l], c.u1), c.dt);
#pragma GCC unroll 8
        for (int k = 0; k < N; ++k) out[k][l] = s[k];
        bad[l] = ok ? 0 : 1;
      }
      std::int64_t any_bad = 0;
      for (std::size_t l = 0; l < n; ++l) any_bad |= bad[l];
      if (any_bad != 0) [[unlikely]] {
        const typename Model::Control u(c.u0, c.u1);
        for (std::size_t l = 0; l < n; ++l) {
          if (bad[l] == 0) continue;
          typename Model::State s;
          for (int k = 0; k < N; ++k) s[k] = in[k][l];
          const double noise[2] = {n0[l], n1[l]};
          const typename Model::State moved = model.sample(s, u, c.dt, sigmas, noise);
          for (int k = 0; k < N; ++k) out[k][l] = moved[k];
        }
      }
    };
    for (std::size_t step = 0; step < steps.size(); ++step) {
      if (step % 2 == 0) {
        step_once(even, odd, step);
      } else {
        step_once(odd, even, step);
      }
    }
    const Rows& result = steps.size() % 2 == 0 ? even : odd;
#pragma GCC unroll 8
    for (int k = 0; k < N; ++k) {
      for (std::size_t l = 0; l < n; ++l) block.col[k][first + l] = result[k][l];
    }
  }
}

// For each step k in order, every lane l: P_l <- J P_l J^T + V M V^T with J =
// jacobian_pose(s_l, u_k, dt_k), V = jacobian_control(s_l, u_k, dt_k), M = diag(sigmas^2) (the
// covariance the pose would have after the step, to first order), then s_l <- predict(s_l,
// u_k, dt_k). REQUIRES: block.lanes % kMotionLanes == 0; cov holds the upper triangles of the
// lanes' covariances.
template <class Model>
void predict_block(const Model& model, const StateBlock<Model::kStateDim>& block,
                   std::span<const ControlStep> steps, const typename Model::Control& sigmas,
                   const CovBlock<Model::kStateDim>& cov) noexcept {
  using L = motion_batch_internal::Lane<Model>;
  using motion_batch_internal::kChunk;
  constexpr int N = Model::kStateDim;
  constexpr int E = kCovEntries<N>;
  constexpr std::size_t T = L::kJacobianPattern.size();
  using Rows = double[N + E][kChunk];  // states, then covariance entries
  const double m0 = sigmas[0] * sigmas[0], m1 = sigmas[1] * sigmas[1];
  for (std::size_t first = 0; first < block.lanes; first += kChunk) {
    const std::size_t n = std::min(kChunk, block.lanes - first);
    alignas(64) Rows even;  // as in sample_block
    alignas(64) Rows odd;
    alignas(64) std::int64_t bad[kChunk];
#pragma GCC unroll 8
    for (int k = 0; k < N; ++k) {
      for (std::size_t l = 0; l < n; ++l) even[k][l] = block.col[k][first + l];
    }
#pragma GCC unroll 16
    for (int e = 0; e < E; ++e) {
      for (std::size_t l = 0; l < n; ++l) even[N + e][l] = cov[e][first + l];
    }
    auto step_once = [&](const Rows& in, Rows& out, const ControlStep& c)
        __attribute__((always_inline)) {
      for (std::size_t l = 0; l < n; ++l) {
        double s[N];
#pragma GCC unroll 8
        for (int k = 0; k < N; ++k) s[k] = in[k][l];
        double p[E];
#pragma GCC unroll 16
        for (int e = 0; e < E; ++e) p[e] = in[N + e][l];
        double j[T];
        double v[N][2];
        L::terms(model, s, c.u0, c.u1, c.dt, j, v);
        motion_batch_internal::propagate<L, N>(p, j, v, m0, m1);
        const bool ok = L::move(model, s, c.u0, c.u1, c.dt);
#pragma GCC unroll 8
        for (int k = 0; k < N; ++k) out[k][l] = s[k];
#pragma GCC unroll 16
        for (int e = 0; e < E; ++e) out[N + e][l] = p[e];
        bad[l] = ok ? 0 : 1;
      }
      std::int64_t any_bad = 0;
      for (std::size_t l = 0; l < n; ++l) any_bad |= bad[l];
      if (any_bad != 0) [[unlikely]] {
        using State = typename Model::State;
        using Cov = typename Model::StateCovariance;
        const typename Model::Control u(c.u0, c.u1);
        const typename Model::ControlCovariance control_cov = Model::control_covariance(sigmas);
        for (std::size_t l = 0; l < n; ++l) {
          if (bad[l] == 0) continue;
          State s;
          for (int k = 0; k < N; ++k) s[k] = in[k][l];
          Cov p;
          for (int r = 0; r < N; ++r) {
            for (int col = r; col < N; ++col) {
              p(r, col) = p(col, r) = in[N + upper_index<N>(r, col)][l];
            }
          }
          const typename Model::StateJacobian j = model.jacobian_pose(s, u, c.dt);
          const Cov moved_cov = j * p * j.transpose() + model.pose_noise(s, u, c.dt, control_cov);
          const State moved = model.predict(s, u, c.dt);
          for (int k = 0; k < N; ++k) out[k][l] = moved[k];
          for (int r = 0; r < N; ++r) {
            for (int col = r; col < N; ++col) {
              out[N + upper_index<N>(r, col)][l] = 0.5 * (moved_cov(r, col) + moved_cov(col, r));
            }
          }
        }
      }
    };
    for (std::size_t step = 0; step < steps.size(); ++step) {
      if (step % 2 == 0) {
        step_once(even, odd, steps[step]);
      } else {
        step_once(odd, even, steps[step]);
      }
    }
    const Rows& result = steps.size() % 2 == 0 ? even : odd;
#pragma GCC unroll 8
    for (int k = 0; k < N; ++k) {
      for (std::size_t l = 0; l < n; ++l) block.col[k][first + l] = result[k][l];
    }
#pragma GCC unroll 16
    for (int e = 0; e < E; ++e) {
      for (std::size_t l = 0; l < n; ++l) cov[e][first + l] = result[N + e][l];
    }
  }
}

}  // namespace fastslam::engine
