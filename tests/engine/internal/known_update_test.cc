// The known-id stage against the scalar per-particle functions of engine/landmark_ekf.h and
// engine/proposal.h: each particle's landmarks, weight, drawn pose and left-over covariance must
// equal a per-particle loop over the scan (up to the lane kernels' rounding), and every
// particle's map only its own.
#include "engine/internal/known_update.h"

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "engine/landmark_ekf.h"
#include "engine/proposal.h"
#include "memory/node_heap.h"

namespace fastslam::engine::internal {
namespace {

constexpr double kTol = 1e-9;

struct World {
  memory::PoolHeap heap;
  memory::ParticleStore store;
  PoseCovariances cov;
  RangeBearingModel sensor{SensorOffset{0.4, 0.1, 0.05}};
  KnownInput in;
  std::vector<PlannedObservation> scan;

  // m particles near the origin sharing a map of `known` landmarks (slots 0..known-1), and a
  // scan observing slots 0..known-1 and then two new landmarks.
  World(std::size_t m, std::size_t known, int n)
      : store(m, heap, {memory::Indexing::kNone, memory::PoseCovariance::kScratch}), cov(store) {
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    in.sensor = &sensor;
    in.r << 0.01, 0, 0, 0.0004;
    in.existence.initial = 0.5;
    in.existence.seen = 0.25;
    in.scan_step = 17;
    memory::LandmarkTree map(heap);
    for (std::size_t k = 0; k < known; ++k) {
      const double a = 0.6 * static_cast<double>(k) - 1.0;
      map.insert({8 * std::cos(a), 8 * std::sin(a), 0.05, 0.01, 0.04, 1.0, k, 3});
    }
    for (std::size_t i = 0; i < m; ++i) {
      store.x()[i] = 0.3 * u(rng);
      store.y()[i] = 0.3 * u(rng);
      store.theta()[i] = 0.1 * u(rng);
      store.v()[i] = 1 + 0.1 * u(rng);
      store.omega()[i] = 0.05 * u(rng);
      store.log_weight()[i] = -1.0 * static_cast<double>(i);
      store.map(i) = memory::ParticleMap(map, memory::Indexing::kNone,
                                         [](const memory::Landmark&) { return 0.0f; });
      if (n > 0) {
        Eigen::MatrixXd a(n, n);
        for (int e = 0; e < n * n; ++e) a.data()[e] = 0.1 * u(rng);
        Eigen::MatrixXd p = a * a.transpose() + 0.001 * Eigen::MatrixXd::Identity(n, n);
        double* slot = cov.values().data() + i * PoseCovariances::kSlot;
        Eigen::Map<Eigen::MatrixXd>(slot, n, n) = p;
      }
    }
    for (std::size_t k = 0; k < known; ++k) {
      const double a = 0.6 * static_cast<double>(k) - 1.0;
      PlannedObservation o;
      o.z = {8.0 + 0.05 * u(rng), a + 0.01 * u(rng)};
      o.slot = static_cast<memory::Slot>(k);
      o.id = k;
      scan.push_back(o);
    }
    for (std::size_t k = 0; k < 2; ++k) {
      PlannedObservation o;
      o.z = {5.0 + static_cast<double>(k), 0.3 * static_cast<double>(k)};
      o.slot = static_cast<memory::Slot>(known + k);
      o.id = 1000 + k;
      o.is_new = true;
      scan.push_back(o);
    }
  }

  Pose pose(std::size_t i) const { return {store.x()[i], store.y()[i], store.theta()[i]}; }
};

void expect_landmark_near(const memory::Landmark& got, const LandmarkGaussian& want) {
  EXPECT_NEAR(got.x, want.mean[0], kTol);
  EXPECT_NEAR(got.y, want.mean[1], kTol);
  EXPECT_NEAR(got.sxx, want.cov(0, 0), kTol);
  EXPECT_NEAR(got.sxy, want.cov(0, 1), kTol);
  EXPECT_NEAR(got.syy, want.cov(1, 1), kTol);
}

TEST(KnownUpdateTest, FastSlam1MatchesTheScalarEkfPerParticle) {
  World w(13, 5, 0);
  World start(13, 5, 0);
  KnownScratch scratch;
  ScanRecords records;
  records.reset(13, w.scan.size());
  update_block_known<true>(w.in, w.scan, w.store, 0, 5, records, scratch);
  update_block_known<true>(w.in, w.scan, w.store, 5, 13, records, scratch);
  for (std::size_t i = 0; i < 13; ++i) {
    double log_w = start.store.log_weight()[i];
    ASSERT_EQ(w.store.map(i).size(), 7u);
    for (std::size_t j = 0; j < w.scan.size(); ++j) {
      const PlannedObservation& o = w.scan[j];
      const memory::Landmark& got = w.store.map(i).at(o.slot);
      const double d2 = records.mahalanobis2(j, i);
      LandmarkGaussian want;
      if (o.is_new) {
        want = initialize_landmark(w.sensor, start.pose(i), o.z, w.in.r);
        EXPECT_EQ(got.log_odds, 0.5);
        EXPECT_EQ(d2, std::numeric_limits<double>::infinity());
      } else {
        want = to_gaussian(start.store.map(i).at(o.slot));
        const LandmarkObservation terms =
            evaluate_observation(w.sensor, want, start.pose(i), o.z, w.in.r);
        EXPECT_NEAR(d2, terms.mahalanobis2, kTol * (1.0 + terms.mahalanobis2));
        log_w += update_landmark(w.sensor, want, start.pose(i), o.z, w.in.r);
        EXPECT_EQ(got.log_odds, 1.25);
      }
      expect_landmark_near(got, want);
      EXPECT_EQ(got.id, o.id);
      EXPECT_EQ(got.last_seen, 17);
    }
    EXPECT_NEAR(w.store.log_weight()[i], log_w, kTol);
  }
}

template <int N>
void expect_proposal_matches_scalar() {
  constexpr std::size_t m = 11;
  World w(m, 4, N);
  World start(m, 4, N);
  std::vector<double> draws(N * m);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> normal;
  for (double& d : draws) d = normal(rng);
  KnownScratch scratch;
  propose_block_known<N>(w.in, w.scan, w.store, w.cov, 0, 3, draws.data(), scratch);
  propose_block_known<N>(w.in, w.scan, w.store, w.cov, 3, m, draws.data() + 3 * N, scratch);
  for (std::size_t i = 0; i < m; ++i) {
    const double all[5] = {start.store.x()[i], start.store.y()[i], start.store.theta()[i],
                           start.store.v()[i], start.store.omega()[i]};
    PoseGaussian<N> proposal;
    for (int k = 0; k < N; ++k) proposal.mean[k] = all[k];
    proposal.cov = start.cov.at<N>(i);
    double log_w = start.store.log_weight()[i];
    for (const PlannedObservation& o : w.scan) {
      if (o.is_new) continue;
      double term = 0.0;
      proposal = fold_observation<N>(w.sensor, proposal, to_gaussian(start.store.map(i).at(o.slot)),
                                     o.z, w.in.r, &term);
      log_w += term;
    }
    Eigen::Matrix<double, N, N> rest;
    const Eigen::Matrix<double, N, 1> s = draw_state<N>(proposal, &draws[N * i], rest);
    const double got[5] = {w.store.x()[i], w.store.y()[i], w.store.theta()[i], w.store.v()[i],
                           w.store.omega()[i]};
    for (int k = 0; k < N; ++k) EXPECT_NEAR(got[k], s[k], 1e-8) << i << " " << k;
    EXPECT_NEAR(w.store.log_weight()[i], log_w, 1e-8);
    const Eigen::Matrix<double, N, N> got_rest = w.cov.at<N>(i);
    EXPECT_TRUE(((got_rest - rest).array().abs() <= 1e-10).all()) << got_rest << "\n\n" << rest;
  }
}

TEST(KnownUpdateTest, FastSlam2ProposalMatchesTheScalarFoldsAndDraw) {
  expect_proposal_matches_scalar<3>();
  expect_proposal_matches_scalar<5>();
}

TEST(KnownUpdateTest, FastSlam2UpdateLeavesTheWeights) {
  World w(9, 3, 0);
  KnownScratch scratch;
  ScanRecords records;
  records.reset(9, w.scan.size());
  update_block_known<false>(w.in, w.scan, w.store, 0, 9, records, scratch);
  for (std::size_t i = 0; i < 9; ++i) {
    EXPECT_EQ(w.store.log_weight()[i], -1.0 * static_cast<double>(i));
    EXPECT_EQ(w.store.map(i).size(), 5u);
  }
}

}  // namespace
}  // namespace fastslam::engine::internal
