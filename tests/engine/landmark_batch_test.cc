// Tests of engine/landmark_batch.h: every lane against the scalar functions (the EKF of
// engine/landmark_ekf.h: evaluate_observation + apply_update; the FastSLAM 2.0 proposal of
// engine/proposal.h: evaluate_proposal + fold, sample_pose) with and without a sensor offset and
// yaw, headings and bearings at the +-pi seam, N = 3 and 5; a lane's bits independent of the
// block size and its position in it (a lane alone, in a scalar remainder, or in a vector); lanes
// outside the vector domain equal the scalar functions bit for bit; no weight pointer changes
// nothing else.
#include "engine/landmark_batch.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <gtest/gtest.h>

#include "engine/landmark_ekf.h"
#include "engine/measurement_model.h"
#include "engine/proposal.h"
#include "tests/engine/test_util.h"

namespace fastslam::engine {
namespace {

using testing::random_heading;

// Lanes as owned columns: pose x, y, theta; landmark x, y, sxx, sxy, syy; log weight.
struct Columns {
  explicit Columns(std::size_t n) : c(9, std::vector<double>(n, 0.0)) {}
  std::vector<std::vector<double>> c;
  PoseLanes pose() const { return {c[0].data(), c[1].data(), c[2].data()}; }
  LandmarkLanes lm() { return {c[3].data(), c[4].data(), c[5].data(), c[6].data(), c[7].data()}; }
  double* log_w() { return c[8].data(); }
  std::size_t size() const { return c[0].size(); }
  void set_lane(std::size_t to, const Columns& from, std::size_t l) {
    for (std::size_t k = 0; k < c.size(); ++k) c[k][to] = from.c[k][l];
  }
};

struct Scene {
  RangeBearingModel sensor;
  Eigen::Matrix2d r;
  Eigen::Vector2d z;
};

// One observation z and per lane a pose and a landmark that z is a plausible sighting of (the
// landmark's true position perturbed), with bearings all around, including the seam.
Columns random_lanes(std::mt19937_64& rng, const Scene& s, std::size_t n) {
  std::uniform_real_distribution<double> pos(-50.0, 50.0);
  std::uniform_real_distribution<double> log_sd(std::log(0.02), std::log(2.0));
  std::uniform_real_distribution<double> corr(-0.9, 0.9);
  std::normal_distribution<double> noise;
  Columns out(n);
  for (std::size_t l = 0; l < n; ++l) {
    const Pose pose(pos(rng), pos(rng), random_heading(rng));
    const Eigen::Vector2d truth = s.sensor.landmark_from(s.z, pose);
    const double a = std::exp(log_sd(rng));
    const double b = std::exp(log_sd(rng));
    const double c = corr(rng);
    const double vals[9] = {
        pose[0],   pose[1], pose[2],   truth[0] + a * noise(rng), truth[1] + b * noise(rng), a * a,
        c * a * b, b * b,   noise(rng)};
    for (int k = 0; k < 9; ++k) out.c[k][l] = vals[k];
  }
  return out;
}

Scene random_setup(std::mt19937_64& rng, bool offset) {
  std::uniform_real_distribution<double> range(1.0, 40.0);
  std::uniform_real_distribution<double> sd(0.01, 0.5);
  Scene s{offset ? RangeBearingModel(SensorOffset{3.78, -0.5, 2.9}) : RangeBearingModel(),
          Eigen::Matrix2d::Zero(), Eigen::Vector2d(range(rng), random_heading(rng))};
  s.r(0, 0) = sd(rng) * sd(rng);
  s.r(1, 1) = 0.01 * sd(rng) * sd(rng);
  return s;
}

// Lane l through the scalar EKF; returns its log-likelihood.
double scalar_lane(const Scene& s, Columns& cols, std::size_t l) {
  LandmarkGaussian g;
  g.mean << cols.c[3][l], cols.c[4][l];
  g.cov << cols.c[5][l], cols.c[6][l], cols.c[6][l], cols.c[7][l];
  const Pose pose(cols.c[0][l], cols.c[1][l], cols.c[2][l]);
  const LandmarkObservation t = evaluate_observation(s.sensor, g, pose, s.z, s.r);
  apply_update(g, t, s.r);
  cols.c[3][l] = g.mean[0];
  cols.c[4][l] = g.mean[1];
  cols.c[5][l] = g.cov(0, 0);
  cols.c[6][l] = g.cov(0, 1);
  cols.c[7][l] = g.cov(1, 1);
  cols.c[8][l] += t.log_likelihood;
  return t.log_likelihood;
}

TEST(LandmarkBatchTest, EveryLaneMatchesTheScalarEkf) {
  std::mt19937_64 rng(41);
  for (const bool offset : {false, true}) {
    for (int trial = 0; trial < 40; ++trial) {
      const Scene s = random_setup(rng, offset);
      const std::size_t n = 8 * (1 + trial % 12);
      Columns lanes = random_lanes(rng, s, n);
      Columns want = lanes;
      for (std::size_t l = 0; l < n; ++l) scalar_lane(s, want, l);
      update_landmark_lanes(s.sensor, s.r, s.z, lanes.pose(), lanes.lm(), lanes.log_w(), n);
      for (std::size_t l = 0; l < n; ++l) {
        SCOPED_TRACE("offset " + std::to_string(offset) + " trial " + std::to_string(trial) +
                     " lane " + std::to_string(l));
        const double scale = std::sqrt(std::max(want.c[5][l], want.c[7][l]));
        EXPECT_NEAR(lanes.c[3][l], want.c[3][l], 1e-11 * scale + 1e-13);
        EXPECT_NEAR(lanes.c[4][l], want.c[4][l], 1e-11 * scale + 1e-13);
        for (int k = 5; k < 8; ++k) EXPECT_NEAR(lanes.c[k][l], want.c[k][l], 1e-11 * scale * scale);
        EXPECT_NEAR(lanes.c[8][l], want.c[8][l], 1e-10 * std::max(1.0, std::fabs(want.c[8][l])));
        EXPECT_EQ(lanes.c[0][l], want.c[0][l]);  // poses are read only
      }
    }
  }
}

// The same lane gives the same bits alone (a scalar loop), at any position of a block of any
// size (vector body or remainder), with or without other lanes falling back.
TEST(LandmarkBatchTest, LaneBitsDependOnTheLaneAlone) {
  std::mt19937_64 rng(43);
  for (const bool offset : {false, true}) {
    const Scene s = random_setup(rng, offset);
    const Columns source = random_lanes(rng, s, 67);
    Columns block = source;
    update_landmark_lanes(s.sensor, s.r, s.z, block.pose(), block.lm(), block.log_w(), 67);
    for (std::size_t l = 0; l < 67; l += 5) {
      Columns alone(1);
      alone.set_lane(0, source, l);
      update_landmark_lanes(s.sensor, s.r, s.z, alone.pose(), alone.lm(), alone.log_w(), 1);
      // Lane l moved to position 13 of a block of 29 whose lane 2 falls back (heading 7 rad).
      Columns moved = random_lanes(rng, s, 29);
      moved.set_lane(13, source, l);
      moved.c[2][2] = 7.0;
      update_landmark_lanes(s.sensor, s.r, s.z, moved.pose(), moved.lm(), moved.log_w(), 29);
      for (std::size_t k = 3; k < 9; ++k) {
        EXPECT_EQ(std::memcmp(&alone.c[k][0], &block.c[k][l], sizeof(double)), 0)
            << "lane " << l << " column " << k;
        EXPECT_EQ(std::memcmp(&moved.c[k][13], &block.c[k][l], sizeof(double)), 0)
            << "lane " << l << " column " << k;
      }
    }
  }
}

// Outside the vector domain (heading beyond pi, landmark on the sensor, non-finite values) a
// lane is the scalar EKF bit for bit, whatever that gives; its neighbours are unaffected.
TEST(LandmarkBatchTest, LanesOutsideTheDomainTakeTheScalarPath) {
  std::mt19937_64 rng(47);
  const Scene s = random_setup(rng, false);
  Columns lanes = random_lanes(rng, s, 16);
  lanes.c[2][1] = 4.0;            // heading beyond pi
  lanes.c[2][4] = -100.0;         // far beyond
  lanes.c[3][6] = lanes.c[0][6];  // landmark on the sensor: q = 0
  lanes.c[4][6] = lanes.c[1][6];
  lanes.c[5][9] = std::numeric_limits<double>::quiet_NaN();
  const Columns before = lanes;
  Columns want = lanes;
  for (const std::size_t l : {1, 4, 6, 9}) scalar_lane(s, want, l);
  update_landmark_lanes(s.sensor, s.r, s.z, lanes.pose(), lanes.lm(), lanes.log_w(), 16);
  for (const std::size_t l : {1, 4, 6, 9}) {
    for (std::size_t k = 3; k < 9; ++k) {
      EXPECT_EQ(std::memcmp(&lanes.c[k][l], &want.c[k][l], sizeof(double)), 0)
          << "lane " << l << " column " << k;
    }
  }
  // The other lanes were updated by the vector path, and match the scalar EKF closely.
  for (const std::size_t l : {0, 2, 3, 5, 7, 8, 10, 15}) {
    Columns one(1);
    one.set_lane(0, before, l);
    scalar_lane(s, one, 0);
    EXPECT_NEAR(lanes.c[3][l], one.c[3][0], 1e-9) << l;
    EXPECT_NEAR(lanes.c[8][l], one.c[8][0], 1e-9) << l;
  }
}

TEST(LandmarkBatchTest, WithoutAWeightTheLandmarksAreTheSame) {
  std::mt19937_64 rng(53);
  const Scene s = random_setup(rng, true);
  Columns with = random_lanes(rng, s, 24);
  Columns without = with;
  update_landmark_lanes(s.sensor, s.r, s.z, with.pose(), with.lm(), with.log_w(), 24);
  update_landmark_lanes(s.sensor, s.r, s.z, without.pose(), without.lm(), nullptr, 24);
  for (std::size_t k = 0; k < 8; ++k) EXPECT_EQ(with.c[k], without.c[k]) << "column " << k;
}

// ---- FastSLAM 2.0 proposal lanes ----------------------------------------------------------

// Proposals as owned columns (N means, the upper triangle) plus landmarks and weights.
template <int N>
struct ProposalColumns {
  static constexpr int E = N * (N + 1) / 2;
  explicit ProposalColumns(std::size_t n) : c(N + E + 6, std::vector<double>(n, 0.0)) {}
  std::vector<std::vector<double>> c;
  ProposalLanes<N> proposal() {
    ProposalLanes<N> p;
    for (int k = 0; k < N; ++k) p.mean[k] = c[k].data();
    for (int e = 0; e < E; ++e) p.cov[e] = c[N + e].data();
    return p;
  }
  ConstLandmarkLanes lm() const {
    return {c[N + E].data(), c[N + E + 1].data(), c[N + E + 2].data(), c[N + E + 3].data(),
            c[N + E + 4].data()};
  }
  double* log_w() { return c[N + E + 5].data(); }
  PoseGaussian<N> gaussian(std::size_t l) const {
    PoseGaussian<N> g;
    for (int i = 0, e = 0; i < N; ++i) {
      g.mean[i] = c[i][l];
      for (int j = i; j < N; ++j, ++e) g.cov(i, j) = g.cov(j, i) = c[N + e][l];
    }
    return g;
  }
  LandmarkGaussian landmark(std::size_t l) const {
    LandmarkGaussian g;
    g.mean << c[N + E][l], c[N + E + 1][l];
    g.cov << c[N + E + 2][l], c[N + E + 3][l], c[N + E + 3][l], c[N + E + 4][l];
    return g;
  }
  void set_lane(std::size_t to, const ProposalColumns& from, std::size_t l) {
    for (std::size_t k = 0; k < c.size(); ++k) c[k][to] = from.c[k][l];
  }
};

// A proposal per lane as the motion prior makes it (rank-2 P = V M V^T for N = 3, a full one for
// N = 5) around a pose, and a landmark that z sights from near that pose.
template <int N>
ProposalColumns<N> random_proposals(std::mt19937_64& rng, const Scene& s, std::size_t n) {
  constexpr int E = ProposalColumns<N>::E;
  std::uniform_real_distribution<double> pos(-50.0, 50.0);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::normal_distribution<double> noise;
  ProposalColumns<N> out(n);
  for (std::size_t l = 0; l < n; ++l) {
    Eigen::Matrix<double, N, 1> mean;
    mean << pos(rng), pos(rng), random_heading(rng), Eigen::Matrix<double, N - 3, 1>::Zero();
    Eigen::Matrix<double, N, N> cov;
    if constexpr (N == 3) {
      Eigen::Matrix<double, 3, 2> v = Eigen::Matrix<double, 3, 2>::Random() * 0.3;
      cov = v * v.transpose();
    } else {
      Eigen::Matrix<double, N, N> a = Eigen::Matrix<double, N, N>::Random() * 0.2;
      cov = a * a.transpose() + 1e-4 * Eigen::Matrix<double, N, N>::Identity();
    }
    const Eigen::Vector2d truth = s.sensor.landmark_from(s.z, mean.template head<3>());
    const double sd = 0.05 + 0.5 * std::fabs(unit(rng));
    for (int i = 0, e = 0; i < N; ++i) {
      out.c[i][l] = mean[i];
      for (int j = i; j < N; ++j, ++e) out.c[N + e][l] = cov(i, j);
    }
    out.c[N + E][l] = truth[0] + sd * noise(rng);
    out.c[N + E + 1][l] = truth[1] + sd * noise(rng);
    out.c[N + E + 2][l] = sd * sd;
    out.c[N + E + 3][l] = 0.3 * sd * sd * unit(rng);
    out.c[N + E + 4][l] = sd * sd;
    out.c[N + E + 5][l] = noise(rng);
  }
  return out;
}

// `weight_scale`: the lanes' weight terms against evaluate_proposal's with the same scale.
template <int N>
void expect_proposals_match(int seed, double weight_scale = 1.0) {
  constexpr int E = ProposalColumns<N>::E;
  std::mt19937_64 rng(seed);
  for (const bool offset : {false, true}) {
    for (int trial = 0; trial < 20; ++trial) {
      const Scene s = random_setup(rng, offset);
      const std::size_t n = 3 + 7 * trial;
      ProposalColumns<N> cols = random_proposals<N>(rng, s, n);
      const ProposalColumns<N> before = cols;
      fold_proposal_lanes<N>(s.sensor, s.r, s.z, cols.proposal(), cols.lm(), cols.log_w(), n,
                             weight_scale);
      std::vector<double> normals(N * n);
      std::normal_distribution<double> noise;
      for (double& x : normals) x = noise(rng);
      std::vector<std::vector<double>> drawn(N, std::vector<double>(n));
      double* state[N];
      for (int k = 0; k < N; ++k) state[k] = drawn[k].data();
      sample_pose_lanes<N>(cols.proposal(), normals.data(), state, n);
      for (std::size_t l = 0; l < n; ++l) {
        SCOPED_TRACE("N " + std::to_string(N) + " offset " + std::to_string(offset) + " trial " +
                     std::to_string(trial) + " lane " + std::to_string(l));
        const PoseGaussian<N> prior = before.gaussian(l);
        ProposalObservation<N> t =
            evaluate_proposal<N>(s.sensor, before.landmark(l), prior, s.z, s.r);
        if (weight_scale != 1.0) scale_weight<N>(t, s.r, weight_scale);
        const PoseGaussian<N> want = fold<N>(prior, t);
        const PoseGaussian<N> got = cols.gaussian(l);
        const double scale = std::sqrt(prior.cov.diagonal().maxCoeff()) + 1e-3;
        for (int i = 0; i < N; ++i) {
          EXPECT_NEAR(got.mean[i], want.mean[i], 1e-11 * scale) << "mean " << i;
          for (int j = 0; j < N; ++j) {
            EXPECT_NEAR(got.cov(i, j), want.cov(i, j), 1e-11 * scale * scale) << i << "," << j;
          }
        }
        const double want_w = before.c[N + E + 5][l] + t.log_likelihood;
        EXPECT_NEAR(cols.c[N + E + 5][l], want_w, 1e-10 * std::max(1.0, std::fabs(want_w)));
        // The draw from the folded proposal (the lanes' own, so only the sampling is compared).
        // psd_factor drops pivots at or below 64 N eps max(diag): rounding can put a pivot of a
        // (near-)singular proposal on either side, which moves the draw by up to about
        // sqrt(threshold) per unit normal (a rank-2 prior folded by one observation is such a
        // case); beyond that the two must agree to rounding.
        const Eigen::Matrix<double, N, 1> pose = sample_pose<N>(got, &normals[N * l]);
        const double threshold = 64.0 * N * 2.220446049250313e-16 * got.cov.diagonal().maxCoeff();
        double largest_normal = 0.0;
        for (int k = 0; k < N; ++k)
          largest_normal = std::max(largest_normal, std::fabs(normals[N * l + k]));
        const double tolerance = 1e-11 * scale + 4.0 * std::sqrt(threshold) * largest_normal;
        for (int k = 0; k < N; ++k) EXPECT_NEAR(drawn[k][l], pose[k], tolerance) << k;
      }
    }
  }
}

TEST(ProposalLanesTest, EveryLaneMatchesEvaluateFoldAndSample) {
  expect_proposals_match<3>(59);
  expect_proposals_match<5>(61);
}

// With a weight scale (FilterConfig::error_correlation) every lane's weight term is
// evaluate_proposal's under the same scale, and the fold and draw are unchanged.
TEST(ProposalLanesTest, ScaledWeightsMatchEvaluateProposal) {
  expect_proposals_match<3>(71, 17.2);
  expect_proposals_match<5>(73, 2.0);
}

TEST(ProposalLanesTest, LaneBitsDependOnTheLaneAloneAndFallbacksAreScalar) {
  std::mt19937_64 rng(67);
  const Scene s = random_setup(rng, true);
  const ProposalColumns<3> source = random_proposals<3>(rng, s, 45);
  ProposalColumns<3> block = source;
  block.c[2][7] = 9.0;  // heading beyond pi: the scalar path
  const ProposalColumns<3> block_before = block;
  fold_proposal_lanes<3>(s.sensor, s.r, s.z, block.proposal(), block.lm(), block.log_w(), 45);
  for (std::size_t l = 0; l < 45; l += 4) {
    ProposalColumns<3> alone(1);
    alone.set_lane(0, block_before, l);
    fold_proposal_lanes<3>(s.sensor, s.r, s.z, alone.proposal(), alone.lm(), alone.log_w(), 1);
    for (std::size_t k = 0; k < alone.c.size(); ++k) {
      EXPECT_EQ(std::memcmp(&alone.c[k][0], &block.c[k][l], sizeof(double)), 0)
          << "lane " << l << " column " << k;
    }
  }
  // The fallback lane is evaluate_proposal + fold bit for bit.
  const PoseGaussian<3> prior = block_before.gaussian(7);
  const ProposalObservation<3> t =
      evaluate_proposal<3>(s.sensor, block_before.landmark(7), prior, s.z, s.r);
  const PoseGaussian<3> want = fold<3>(prior, t);
  const PoseGaussian<3> got = block.gaussian(7);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(got.mean[i], want.mean[i]);
    for (int j = i; j < 3; ++j) EXPECT_EQ(got.cov(i, j), want.cov(i, j));
  }
  EXPECT_EQ(block.c[3 + 6 + 5][7], block_before.c[3 + 6 + 5][7] + t.log_likelihood);
  // Scaled, the fallback lane's weight term is evaluate_proposal's with the scale.
  ProposalColumns<3> scaled = block_before;
  fold_proposal_lanes<3>(s.sensor, s.r, s.z, scaled.proposal(), scaled.lm(), scaled.log_w(), 45,
                         5.0);
  ProposalObservation<3> ts = t;
  scale_weight<3>(ts, s.r, 5.0);
  EXPECT_EQ(scaled.c[3 + 6 + 5][7], block_before.c[3 + 6 + 5][7] + ts.log_likelihood);
  EXPECT_EQ(scaled.gaussian(7).mean[0], want.mean[0]);
}

}  // namespace
}  // namespace fastslam::engine
