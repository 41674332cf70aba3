// Tests of engine/motion_batch.h against the scalar models of engine/motion_model.h (the
// oracle): every model's sample_block against repeated sample, predict_block against repeated
// predict and the dense Eigen covariance J P J^T + V M V^T, the scalar fallback for lanes
// outside the vector path's domain, and bit equality for any blocking (a particle's result must
// not depend on the block it is in or its lane, or a filter run would depend on the grain).
#include "engine/motion_batch.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <random>
#include <span>
#include <vector>

#include <Eigen/Core>
#include <gtest/gtest.h>

#include "engine/angles.h"
#include "engine/motion_model.h"
#include "tests/engine/test_util.h"

namespace fastslam::engine {
namespace {

using testing::matrices_near;

constexpr double kTol = 1e-12;  // relative to the scale of each value (max(1, |value|))

// A block of particles with their states, covariances and per-step normals, in the batch
// layout and as scalar values for the oracle.
template <class Model>
struct Fixture {
  static constexpr int N = Model::kStateDim;
  using State = typename Model::State;
  using Cov = typename Model::StateCovariance;

  std::size_t count = 0;
  std::size_t lanes = 0;
  std::vector<double> columns;      // N columns of `lanes`
  std::vector<double> cov_columns;  // kCovEntries<N> columns of `lanes`
  std::vector<double> normals;      // 2 per step, `lanes` each
  std::vector<ControlStep> steps;

  StateBlock<N> block() {
    StateBlock<N> b;
    b.lanes = lanes;
    for (int k = 0; k < N; ++k) b.col[k] = columns.data() + k * lanes;
    return b;
  }
  CovBlock<N> cov() {
    CovBlock<N> c{};
    for (int e = 0; e < kCovEntries<N>; ++e) c[e] = cov_columns.data() + e * lanes;
    return c;
  }
  State state(std::size_t i) const {
    State s;
    for (int k = 0; k < N; ++k) s[k] = columns[k * lanes + i];
    return s;
  }
  void set_state(std::size_t i, const State& s) {
    for (int k = 0; k < N; ++k) columns[k * lanes + i] = s[k];
  }
  Cov covariance(std::size_t i) const {
    Cov p;
    for (int r = 0; r < N; ++r) {
      for (int c = r; c < N; ++c) p(r, c) = p(c, r) = cov_columns[upper_index<N>(r, c) * lanes + i];
    }
    return p;
  }
  void set_covariance(std::size_t i, const Cov& p) {
    for (int r = 0; r < N; ++r) {
      for (int c = r; c < N; ++c) cov_columns[upper_index<N>(r, c) * lanes + i] = p(r, c);
    }
  }
  double normal(std::size_t step, int which, std::size_t i) const {
    return normals[(2 * step + which) * lanes + i];
  }
};

// Random states, SPD covariances, controls and normals for `count` particles and `k` steps.
// `control` draws one step's control and dt.
template <class Model, class DrawState, class DrawControl>
Fixture<Model> make_fixture(std::size_t count, std::size_t k, std::mt19937_64& rng,
                            DrawState&& draw_state, DrawControl&& draw_control) {
  constexpr int N = Model::kStateDim;
  Fixture<Model> f;
  f.count = count;
  f.lanes = padded_lanes(count);
  f.columns.assign(N * f.lanes, 0.0);
  f.cov_columns.assign(kCovEntries<N> * f.lanes, 0.0);
  f.normals.assign(2 * k * f.lanes, 0.0);
  std::normal_distribution<double> gauss;
  for (std::size_t i = 0; i < count; ++i) {
    f.set_state(i, draw_state(rng));
    Eigen::Matrix<double, N, N> a;
    for (int r = 0; r < N; ++r) {
      for (int c = 0; c < N; ++c) a(r, c) = 0.1 * gauss(rng);
    }
    f.set_covariance(i, a * a.transpose());
  }
  for (std::size_t s = 0; s < k; ++s) {
    f.steps.push_back(draw_control(rng));
    for (std::size_t i = 0; i < count; ++i) {
      f.normals[(2 * s) * f.lanes + i] = gauss(rng);
      f.normals[(2 * s + 1) * f.lanes + i] = gauss(rng);
    }
  }
  return f;
}

template <class Model>
void expect_states_near(const typename Model::State& got, const typename Model::State& want,
                        std::size_t i) {
  for (int k = 0; k < Model::kStateDim; ++k) {
    const double diff = k == 2 ? angle_diff(got[k], want[k]) : got[k] - want[k];
    EXPECT_LE(std::abs(diff), kTol * std::max(1.0, std::abs(want[k])))
        << "particle " << i << " component " << k << ": " << got[k] << " vs " << want[k];
  }
}

// sample_block over all steps == repeated scalar sample, for every particle.
template <class Model>
void check_sample(const Model& model, Fixture<Model> f, const typename Model::Control& sigmas) {
  const Fixture<Model> before = f;
  sample_block(model, f.block(), f.steps, sigmas, f.normals.data());
  for (std::size_t i = 0; i < f.count; ++i) {
    typename Model::State s = before.state(i);
    for (std::size_t k = 0; k < f.steps.size(); ++k) {
      const double n[2] = {before.normal(k, 0, i), before.normal(k, 1, i)};
      s = model.sample(s, {f.steps[k].u0, f.steps[k].u1}, f.steps[k].dt, sigmas, n);
    }
    expect_states_near<Model>(f.state(i), s, i);
    EXPECT_TRUE(f.state(i)[2] > -kPi && f.state(i)[2] <= kPi);
  }
}

// predict_block over all steps == repeated predict and J P J^T + V M V^T (dense, Eigen).
template <class Model>
void check_predict(const Model& model, Fixture<Model> f, const typename Model::Control& sigmas) {
  const Fixture<Model> before = f;
  predict_block(model, f.block(), f.steps, sigmas, f.cov());
  const typename Model::ControlCovariance m = Model::control_covariance(sigmas);
  for (std::size_t i = 0; i < f.count; ++i) {
    typename Model::State s = before.state(i);
    typename Model::StateCovariance p = before.covariance(i);
    for (const ControlStep& c : f.steps) {
      const typename Model::Control u(c.u0, c.u1);
      const typename Model::StateJacobian j = model.jacobian_pose(s, u, c.dt);
      p = j * p * j.transpose() + model.pose_noise(s, u, c.dt, m);
      s = model.predict(s, u, c.dt);
    }
    expect_states_near<Model>(f.state(i), s, i);
    EXPECT_TRUE(
        matrices_near(f.covariance(i), p, kTol * std::max(1.0, p.cwiseAbs().maxCoeff()), kTol))
        << "particle " << i;
  }
}

// The same particles in one block, one by one in blocks of their own, and in reversed order:
// identical bits after sample_block and predict_block.
template <class Model>
void check_blocking_invariance(const Model& model, const Fixture<Model>& f,
                               const typename Model::Control& sigmas) {
  constexpr int N = Model::kStateDim;
  Fixture<Model> whole = f;
  sample_block(model, whole.block(), f.steps, sigmas, whole.normals.data());
  Fixture<Model> whole2 = f;
  predict_block(model, whole2.block(), f.steps, sigmas, whole2.cov());
  Fixture<Model> reversed = f;
  for (std::size_t i = 0; i < f.count; ++i) {
    const std::size_t j = f.count - 1 - i;
    reversed.set_state(j, f.state(i));
    reversed.set_covariance(j, f.covariance(i));
    for (std::size_t k = 0; k < f.steps.size(); ++k) {
      for (int w = 0; w < 2; ++w) reversed.normals[(2 * k + w) * f.lanes + j] = f.normal(k, w, i);
    }
  }
  Fixture<Model> reversed2 = reversed;
  sample_block(model, reversed.block(), f.steps, sigmas, reversed.normals.data());
  predict_block(model, reversed2.block(), f.steps, sigmas, reversed2.cov());
  for (std::size_t i = 0; i < f.count; ++i) {
    // Alone: lane 3 of a block of kMotionLanes zero lanes.
    Fixture<Model> alone;
    alone.count = kMotionLanes;
    alone.lanes = kMotionLanes;
    alone.columns.assign(N * kMotionLanes, 0.0);
    alone.cov_columns.assign(kCovEntries<N> * kMotionLanes, 0.0);
    alone.normals.assign(2 * f.steps.size() * kMotionLanes, 0.0);
    alone.steps = f.steps;
    alone.set_state(3, f.state(i));
    alone.set_covariance(3, f.covariance(i));
    for (std::size_t k = 0; k < f.steps.size(); ++k) {
      for (int w = 0; w < 2; ++w) alone.normals[(2 * k + w) * kMotionLanes + 3] = f.normal(k, w, i);
    }
    Fixture<Model> alone2 = alone;
    sample_block(model, alone.block(), f.steps, sigmas, alone.normals.data());
    predict_block(model, alone2.block(), f.steps, sigmas, alone2.cov());
    const std::size_t j = f.count - 1 - i;
    for (int k = 0; k < N; ++k) {
      ASSERT_EQ(std::memcmp(&alone.columns[k * kMotionLanes + 3], &whole.columns[k * f.lanes + i],
                            sizeof(double)),
                0)
          << "sample, particle " << i << " component " << k;
      ASSERT_EQ(std::memcmp(&reversed.columns[k * f.lanes + j], &whole.columns[k * f.lanes + i],
                            sizeof(double)),
                0);
      ASSERT_EQ(std::memcmp(&alone2.columns[k * kMotionLanes + 3], &whole2.columns[k * f.lanes + i],
                            sizeof(double)),
                0)
          << "predict, particle " << i << " component " << k;
      ASSERT_EQ(std::memcmp(&reversed2.columns[k * f.lanes + j], &whole2.columns[k * f.lanes + i],
                            sizeof(double)),
                0);
    }
    for (int e = 0; e < kCovEntries<N>; ++e) {
      ASSERT_EQ(std::memcmp(&alone2.cov_columns[e * kMotionLanes + 3],
                            &whole2.cov_columns[e * f.lanes + i], sizeof(double)),
                0)
          << "covariance, particle " << i << " entry " << e;
      ASSERT_EQ(std::memcmp(&reversed2.cov_columns[e * f.lanes + j],
                            &whole2.cov_columns[e * f.lanes + i], sizeof(double)),
                0);
    }
  }
}

double uniform(std::mt19937_64& rng, double lo, double hi) {
  return std::uniform_real_distribution<double>(lo, hi)(rng);
}

Eigen::Vector3d random_pose(std::mt19937_64& rng) {
  return {uniform(rng, -300, 300), uniform(rng, -300, 300), testing::random_heading(rng)};
}

// Counts that exercise one partial group, several groups and more than one 64-lane chunk.
constexpr std::array<std::size_t, 4> kCounts = {1, 13, 64, 150};

TEST(MotionBatchTest, BaileyCarMatchesTheScalarModel) {
  std::mt19937_64 rng(1);
  const BaileyCarModel model(4.0);
  const Eigen::Vector2d sigmas(0.3, 3.0 * kPi / 180);
  for (const std::size_t count : kCounts) {
    auto f = make_fixture<BaileyCarModel>(count, 6, rng, random_pose, [](std::mt19937_64& r) {
      return ControlStep{uniform(r, 0, 5), uniform(r, -0.6, 0.6), uniform(r, 0.01, 0.3)};
    });
    check_sample(model, f, sigmas);
    check_predict(model, f, sigmas);
    check_blocking_invariance(model, f, sigmas);
  }
}

TEST(MotionBatchTest, UnicycleMatchesTheScalarModel) {
  std::mt19937_64 rng(2);
  const UnicycleModel model;
  const Eigen::Vector2d sigmas(0.2, 0.05);
  for (const std::size_t count : kCounts) {
    auto f = make_fixture<UnicycleModel>(count, 6, rng, random_pose, [](std::mt19937_64& r) {
      return ControlStep{uniform(r, -2, 5), uniform(r, -1.5, 1.5), uniform(r, 0.01, 0.5)};
    });
    check_sample(model, f, sigmas);
    check_predict(model, f, sigmas);
    check_blocking_invariance(model, f, sigmas);
  }
}

TEST(MotionBatchTest, AckermannMatchesTheScalarModel) {
  std::mt19937_64 rng(3);
  const AckermannModel model(testing::kVictoriaParkCar);
  const Eigen::Vector2d sigmas(0.5, 2.0 * kPi / 180);
  for (const std::size_t count : kCounts) {
    auto f = make_fixture<AckermannModel>(count, 6, rng, random_pose, [](std::mt19937_64& r) {
      return ControlStep{uniform(r, 0, 6), uniform(r, -0.5, 0.5), uniform(r, 0.01, 0.2)};
    });
    check_sample(model, f, sigmas);
    check_predict(model, f, sigmas);
    check_blocking_invariance(model, f, sigmas);
  }
}

TEST(MotionBatchTest, BrownianMatchesTheScalarModel) {
  std::mt19937_64 rng(4);
  const BrownianVelocityModel model;
  const Eigen::Vector2d sigmas(0.1, 0.02);
  auto state = [](std::mt19937_64& r) {
    BrownianVelocityModel::State s;
    s << uniform(r, -300, 300), uniform(r, -300, 300), testing::random_heading(r),
        uniform(r, -3, 3), uniform(r, -1, 1);
    return s;
  };
  for (const std::size_t count : kCounts) {
    auto f = make_fixture<BrownianVelocityModel>(count, 6, rng, state, [](std::mt19937_64& r) {
      return ControlStep{uniform(r, -0.1, 0.1), uniform(r, -0.05, 0.05), uniform(r, 0.01, 0.2)};
    });
    check_sample(model, f, sigmas);
    check_predict(model, f, sigmas);
    check_blocking_invariance(model, f, sigmas);
  }
}

TEST(MotionBatchTest, BrownianCurvatureMatchesTheScalarModel) {
  std::mt19937_64 rng(6);
  const BrownianCurvatureModel model;
  const Eigen::Vector2d sigmas(0.1, 0.01);
  // Speeds of both signs, curvatures of both signs (radii down to 2 m).
  auto state = [](std::mt19937_64& r) {
    BrownianCurvatureModel::State s;
    s << uniform(r, -300, 300), uniform(r, -300, 300), testing::random_heading(r),
        uniform(r, -3, 3), uniform(r, -0.5, 0.5);
    return s;
  };
  for (const std::size_t count : kCounts) {
    auto f = make_fixture<BrownianCurvatureModel>(count, 6, rng, state, [](std::mt19937_64& r) {
      return ControlStep{uniform(r, -0.1, 0.1), uniform(r, -0.02, 0.02), uniform(r, 0.01, 0.2)};
    });
    check_sample(model, f, sigmas);
    check_predict(model, f, sigmas);
    check_blocking_invariance(model, f, sigmas);
  }
}

// A lane's `terms` are the scalar Jacobians: I + the kJacobianPattern entries == jacobian_pose
// (so the pattern lists every entry off the identity) and V == jacobian_control.
template <class Model, class DrawState>
void check_lane_terms(const Model& model, DrawState&& draw_state, std::mt19937_64& rng) {
  using L = motion_batch_internal::Lane<Model>;
  constexpr int N = Model::kStateDim;
  for (int trial = 0; trial < 200; ++trial) {
    const typename Model::State s = draw_state(rng);
    const typename Model::Control u(uniform(rng, -0.5, 3.0), uniform(rng, -0.3, 0.3));
    const double dt = uniform(rng, 0.01, 0.3);
    double lane_s[N];
    for (int k = 0; k < N; ++k) lane_s[k] = s[k];
    double j[L::kJacobianPattern.size()];
    double v[N][2];
    L::terms(model, lane_s, u[0], u[1], dt, j, v);
    typename Model::StateJacobian lane_j = Model::StateJacobian::Identity();
    for (std::size_t e = 0; e < L::kJacobianPattern.size(); ++e) {
      lane_j(L::kJacobianPattern[e][0], L::kJacobianPattern[e][1]) = j[e];
    }
    typename Model::ControlJacobian lane_v;
    for (int r = 0; r < N; ++r) lane_v.row(r) << v[r][0], v[r][1];
    ASSERT_TRUE(matrices_near(lane_j, model.jacobian_pose(s, u, dt), kTol, kTol))
        << "s = " << s.transpose() << ", u = " << u.transpose();
    ASSERT_TRUE(matrices_near(lane_v, model.jacobian_control(s, u, dt), kTol, kTol))
        << "s = " << s.transpose() << ", u = " << u.transpose();
    // move == predict.
    const bool ok = L::move(model, lane_s, u[0], u[1], dt);
    ASSERT_TRUE(ok);
    typename Model::State moved;
    for (int k = 0; k < N; ++k) moved[k] = lane_s[k];
    expect_states_near<Model>(moved, model.predict(s, u, dt), 0);
  }
}

TEST(MotionBatchTest, LaneTermsAreTheScalarJacobians) {
  std::mt19937_64 rng(7);
  check_lane_terms(BaileyCarModel(4.0), random_pose, rng);
  check_lane_terms(UnicycleModel(), random_pose, rng);
  check_lane_terms(AckermannModel(testing::kVictoriaParkCar), random_pose, rng);
  auto walk = [](std::mt19937_64& r) {
    Eigen::Matrix<double, 5, 1> s;
    s << uniform(r, -300, 300), uniform(r, -300, 300), testing::random_heading(r),
        uniform(r, -3, 3), uniform(r, -0.5, 0.5);
    return s;
  };
  check_lane_terms(BrownianVelocityModel(), walk, rng);
  check_lane_terms(BrownianCurvatureModel(), walk, rng);
}

// Lanes outside the vector path's domain take the scalar model (same bits as it), and their
// neighbours in the group are unaffected: a steering angle beyond 2^20 rad (sin/cos domain) and
// a heading step of many turns (beyond wrap_near's single shift).
TEST(MotionBatchTest, LanesOutsideTheVectorDomainUseTheScalarModel) {
  const BaileyCarModel bailey(4.0);
  const UnicycleModel unicycle;
  const Eigen::Vector2d sigmas(0.3, 0.05);
  std::mt19937_64 rng(5);
  auto f = make_fixture<BaileyCarModel>(16, 1, rng, random_pose, [](std::mt19937_64&) {
    return ControlStep{3.0, 0.1, 0.1};
  });
  Fixture<BaileyCarModel> huge_steer = f;
  huge_steer.steps[0].u1 = 3e6;  // every lane's steering is beyond the domain
  Fixture<BaileyCarModel> mixed = f;
  mixed.normals[mixed.lanes + 5] = 2e8;   // lane 5's perturbed steering 1e7 rad
  mixed.normals[mixed.lanes + 7] = 16.0;  // lane 7's 0.9 rad: beyond sincos_small's domain
  const Fixture<BaileyCarModel> before = mixed;
  sample_block(bailey, mixed.block(), mixed.steps, sigmas, mixed.normals.data());
  sample_block(bailey, f.block(), f.steps, sigmas, f.normals.data());
  const double n5[2] = {before.normal(0, 0, 5), before.normal(0, 1, 5)};
  const Eigen::Vector3d want5 = bailey.sample(before.state(5), {3.0, 0.1}, 0.1, sigmas, n5);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(mixed.state(5)[k], want5[k]) << k;
  // Lane 7 is within sincos's domain: the scalar model's value up to rounding (the -O1 asan
  // build contracts the scalar model's products differently at its two call sites).
  const double n7[2] = {before.normal(0, 0, 7), before.normal(0, 1, 7)};
  expect_states_near<BaileyCarModel>(
      mixed.state(7), bailey.sample(before.state(7), {3.0, 0.1}, 0.1, sigmas, n7), 7);
  for (std::size_t i = 0; i < 16; ++i) {
    if (i == 5 || i == 7) continue;
    for (int k = 0; k < 3; ++k) EXPECT_EQ(mixed.state(i)[k], f.state(i)[k]) << i;
  }
  const Fixture<BaileyCarModel> huge_before = huge_steer;
  sample_block(bailey, huge_steer.block(), huge_steer.steps, sigmas, huge_steer.normals.data());
  predict_block(bailey, huge_steer.block(), huge_steer.steps, sigmas, huge_steer.cov());
  for (std::size_t i = 0; i < 16; ++i) {
    const double n[2] = {huge_before.normal(0, 0, i), huge_before.normal(0, 1, i)};
    Eigen::Vector3d want = bailey.sample(huge_before.state(i), {3.0, 3e6}, 0.1, sigmas, n);
    want = bailey.predict(want, {3.0, 3e6}, 0.1);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(huge_steer.state(i)[k], want[k]) << i;
  }

  // A turn rate of 300 rad/s for 0.2 s: 60 rad, many turns; wrapped like the scalar model.
  auto u = make_fixture<UnicycleModel>(8, 1, rng, random_pose, [](std::mt19937_64&) {
    return ControlStep{1.0, 300.0, 0.2};
  });
  const Fixture<UnicycleModel> u_before = u;
  sample_block(unicycle, u.block(), u.steps, sigmas, u.normals.data());
  for (std::size_t i = 0; i < 8; ++i) {
    const double n[2] = {u_before.normal(0, 0, i), u_before.normal(0, 1, i)};
    const Eigen::Vector3d want = unicycle.sample(u_before.state(i), {1.0, 300.0}, 0.2, sigmas, n);
    for (int k = 0; k < 3; ++k) EXPECT_EQ(u.state(i)[k], want[k]) << i;
    EXPECT_TRUE(u.state(i)[2] > -kPi && u.state(i)[2] <= kPi);
  }
}

// The curvature walk's heading step v' kappa' dt of many turns (50 m/s on a 1 m radius for
// 0.5 s: 25 rad) takes the scalar path, in sample_block and predict_block.
TEST(MotionBatchTest, CurvatureStepsOfManyTurnsUseTheScalarModel) {
  const BrownianCurvatureModel model;
  const Eigen::Vector2d sigmas(0.1, 0.01);
  std::mt19937_64 rng(8);
  auto f = make_fixture<BrownianCurvatureModel>(
      8, 1, rng,
      [](std::mt19937_64& r) {
        BrownianCurvatureModel::State s;
        s << 0.0, 0.0, testing::random_heading(r), 50.0, uniform(r, 0.9, 1.1);
        return s;
      },
      [](std::mt19937_64&) {
        return ControlStep{0.0, 0.0, 0.5};
      });
  check_sample(model, f, sigmas);
  check_predict(model, f, sigmas);
}

// Headings crossing the seam at +-pi wrap exactly as wrap_angle does (pi stays pi, -pi maps
// to pi), on the vector path.
TEST(MotionBatchTest, HeadingsWrapLikeWrapAngle) {
  const UnicycleModel unicycle;
  Fixture<UnicycleModel> f;
  f.count = f.lanes = kMotionLanes;
  f.columns.assign(3 * kMotionLanes, 0.0);
  f.normals.assign(2 * kMotionLanes, 0.0);
  const double headings[kMotionLanes] = {kPi, -kPi + 1e-9, kPi - 1e-9, 0.5, -3.0, 3.0, 1.0, -1.0};
  const double steps[kMotionLanes] = {0.0, -2e-9, 2e-9, 6.0, -0.5, 0.5, -6.0, 6.2};
  for (std::size_t l = 0; l < kMotionLanes; ++l) {
    f.columns[2 * kMotionLanes + l] = headings[l];
    f.normals[kMotionLanes + l] = steps[l];  // omega = sigma * n with sigma = 1, dt = 1
  }
  f.steps = {ControlStep{0.0, 0.0, 1.0}};
  sample_block(unicycle, f.block(), f.steps, Eigen::Vector2d(0.0, 1.0), f.normals.data());
  for (std::size_t l = 0; l < kMotionLanes; ++l) {
    EXPECT_EQ(f.columns[2 * kMotionLanes + l], wrap_angle(headings[l] + steps[l])) << l;
  }
}

}  // namespace
}  // namespace fastslam::engine
