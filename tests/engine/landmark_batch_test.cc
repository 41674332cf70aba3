// Tests of engine/landmark_batch.h: every lane against the scalar EKF of engine/landmark_ekf.h
// (evaluate_observation + apply_update) with and without a sensor offset and yaw, headings and
// bearings at the +-pi seam; a lane's bits independent of the block size and its position in it
// (a lane alone, in a scalar remainder, or in a vector); lanes outside the vector domain equal
// the scalar functions bit for bit; no weight pointer changes nothing else.
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

}  // namespace
}  // namespace fastslam::engine
