// FastSLAM 2.0's fold-and-draw under unknown association against the lane kernels of
// engine/landmark_batch.h (an independent implementation of the same folds) and against
// draw_state from the motion prior when the association chose no landmark.
#include "engine/internal/fs2_draw.h"

#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "engine/landmark_batch.h"
#include "memory/node_heap.h"

namespace fastslam::engine::internal {
namespace {

struct World {
  memory::PoolHeap heap;
  memory::LandmarkTree map{heap};
  RangeBearingModel sensor{SensorOffset{0.2, 0.1, 0.0}};
  Eigen::Matrix2d r;
  std::vector<PlannedObservation> scan;
  std::vector<std::int64_t> chosen;
  PoseGaussian<5> prior;
  double normals[5] = {0.3, -1.2, 0.7, 0.5, -0.4};

  World() {
    r << 0.02, 0, 0, 0.0005;
    prior.mean << 1.0, 2.0, 0.3, 1.5, 0.1;
    Eigen::Matrix<double, 5, 5> a = Eigen::Matrix<double, 5, 5>::Zero();
    for (int i = 0; i < 5; ++i) {
      for (int j = 0; j <= i; ++j) a(i, j) = 0.05 / (1 + i + j);
    }
    prior.cov = a * a.transpose() + 1e-4 * Eigen::Matrix<double, 5, 5>::Identity();
    for (int k = 0; k < 6; ++k) {
      const memory::Landmark l{6.0 + k, -3.0 + 1.5 * k, 0.1, 0.02, 0.08, 1, 0, 0};
      const memory::Slot slot = map.insert(l);
      const Pose pose = prior.mean.head<3>();
      PlannedObservation o;
      o.z = sensor.predict({l.x + 0.1, l.y - 0.05}, pose);
      scan.push_back(o);
      chosen.push_back(k % 3 == 2 ? kNewLandmark : static_cast<std::int64_t>(slot));
    }
  }
};

TEST(Fs2DrawTest, NoChoiceDrawsFromThePrior) {
  World w;
  const std::vector<std::int64_t> none(w.scan.size(), kNewLandmark);
  const std::vector<double> log_p0(w.scan.size(), -7.0);
  const Fs2Draw<5> d =
      fold_and_draw<5>(w.sensor, w.r, log_p0, w.prior, w.map, w.scan, none, w.normals);
  Eigen::Matrix<double, 5, 5> rest;
  const Eigen::Matrix<double, 5, 1> s = draw_state<5>(w.prior, w.normals, rest);
  EXPECT_EQ(d.state, s);
  EXPECT_EQ(d.rest, rest);
  EXPECT_EQ(d.folded, -7.0 * static_cast<double>(w.scan.size()));
}

TEST(Fs2DrawTest, FoldsMatchTheLaneKernels) {
  World w;
  const std::vector<double> log_p0(w.scan.size(), -7.0);
  const Fs2Draw<5> d =
      fold_and_draw<5>(w.sensor, w.r, log_p0, w.prior, w.map, w.scan, w.chosen, w.normals);
  // One lane (padded to a group) through the lane kernels.
  constexpr std::size_t kLanes = 8;
  std::vector<double> columns((5 + 15 + 6) * kLanes, 0.0);
  auto column = [&](int c) { return columns.data() + c * kLanes; };
  ProposalLanes<5> lanes;
  for (int k = 0; k < 5; ++k) {
    lanes.mean[k] = column(k);
    std::fill_n(lanes.mean[k], kLanes, w.prior.mean[k]);
  }
  for (int row = 0, e = 0; row < 5; ++row) {
    for (int c = row; c < 5; ++c, ++e) {
      lanes.cov[e] = column(5 + e);
      std::fill_n(lanes.cov[e], kLanes, w.prior.cov(row, c));
    }
  }
  double folded = 0.0;
  for (std::size_t j = 0; j < w.scan.size(); ++j) {
    if (w.chosen[j] == kNewLandmark) {
      folded += -7.0;
      continue;
    }
    const memory::Landmark& l = w.map.at(static_cast<memory::Slot>(w.chosen[j]));
    std::vector<double> lm[5];
    for (auto& v : lm) v.assign(kLanes, 0.0);
    std::fill(lm[0].begin(), lm[0].end(), l.x);
    std::fill(lm[1].begin(), lm[1].end(), l.y);
    std::fill(lm[2].begin(), lm[2].end(), l.sxx);
    std::fill(lm[3].begin(), lm[3].end(), l.sxy);
    std::fill(lm[4].begin(), lm[4].end(), l.syy);
    std::vector<double> log_w(kLanes, 0.0);
    fold_proposal_lanes<5>(w.sensor, w.r, w.scan[j].z, lanes,
                           {lm[0].data(), lm[1].data(), lm[2].data(), lm[3].data(), lm[4].data()},
                           log_w.data(), kLanes);
    folded += log_w[0];
  }
  EXPECT_NEAR(d.folded, folded, 1e-9);
  PoseGaussian<5> proposal;
  for (int k = 0; k < 5; ++k) proposal.mean[k] = lanes.mean[k][0];
  for (int row = 0, e = 0; row < 5; ++row) {
    for (int c = row; c < 5; ++c, ++e)
      proposal.cov(row, c) = proposal.cov(c, row) = lanes.cov[e][0];
  }
  Eigen::Matrix<double, 5, 5> rest;
  const Eigen::Matrix<double, 5, 1> s = draw_state<5>(proposal, w.normals, rest);
  for (int k = 0; k < 5; ++k) EXPECT_NEAR(d.state[k], s[k], 1e-9);
  EXPECT_TRUE(((d.rest - rest).array().abs() <= 1e-10).all());
  EXPECT_NE(d.state, draw_state<5>(w.prior, w.normals, rest));  // the folds moved the draw
}

}  // namespace
}  // namespace fastslam::engine::internal
