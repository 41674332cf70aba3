// The scan plan against a brute-force oracle: a std::map of the ids seen so far, slots handed out
// in order of first appearance; and every refusal of predict, observe and set_map.
#include "engine/internal/scan_plan.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <random>
#include <stdexcept>
#include <vector>

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

#include "engine/angles.h"

namespace fastslam::engine::internal {
namespace {

TEST(ScanPlanTest, KnownIdsMatchAnOrderedTableOfFirstAppearances) {
  std::mt19937_64 rng(7);
  std::map<std::int64_t, memory::Slot> oracle;
  KnownSlots known;
  for (int scan_index = 0; scan_index < 50; ++scan_index) {
    std::vector<std::int64_t> ids(40);
    std::iota(ids.begin(), ids.end(), 0);
    std::shuffle(ids.begin(), ids.end(), rng);
    ids.resize(rng() % 12);
    std::vector<Observation> scan;
    for (std::int64_t id : ids) scan.push_back({1.0 + id, 0.1 * id - 7.0, id});
    const ScanPlan plan = plan_scan(scan, Association::kKnown, known);
    ASSERT_EQ(plan.observations.size(), scan.size());
    std::size_t next = oracle.size();
    for (std::size_t j = 0; j < scan.size(); ++j) {
      const PlannedObservation& p = plan.observations[j];
      EXPECT_EQ(p.z[0], scan[j].range);
      EXPECT_EQ(p.z[1], wrap_angle(scan[j].bearing));
      EXPECT_EQ(p.id, static_cast<std::uint64_t>(scan[j].id));
      const auto found = oracle.find(scan[j].id);
      EXPECT_EQ(p.is_new, found == oracle.end());
      EXPECT_EQ(p.slot, found == oracle.end() ? next++ : found->second);
    }
    for (const PlannedObservation& p : plan.observations) {
      if (p.is_new) oracle.emplace(static_cast<std::int64_t>(p.id), p.slot);
    }
    known.merge(KnownSlots(plan.new_slots));
    EXPECT_EQ(known.size(), oracle.size());
  }
}

TEST(ScanPlanTest, UnknownAssociationKeepsMeasurementsOnly) {
  const std::vector<Observation> scan = {{2.0, 4.0, -1}, {3.0, -0.5, 17}};
  const ScanPlan plan = plan_scan(scan, Association::kMaximumLikelihood, {});
  ASSERT_EQ(plan.observations.size(), 2u);
  EXPECT_EQ(plan.observations[0].z[1], wrap_angle(4.0));
  EXPECT_FALSE(plan.observations[1].is_new);
  EXPECT_TRUE(plan.new_slots.empty());
}

TEST(ScanPlanTest, RefusesBadObservations) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (const Observation& bad :
       {Observation{0.0, 0.0, 1}, Observation{-1.0, 0.0, 1}, Observation{nan, 0.0, 1},
        Observation{1.0, nan, 1}, Observation{1.0, std::numeric_limits<double>::infinity(), 1}}) {
    const std::vector<Observation> scan = {{1.0, 0.0, 0}, bad};
    EXPECT_THROW(plan_scan(scan, Association::kKnown, {}), std::invalid_argument);
    EXPECT_THROW(plan_scan(scan, Association::kDataAssociationSampling, {}), std::invalid_argument);
  }
  const std::vector<Observation> negative = {{1.0, 0.0, -3}};
  EXPECT_THROW(plan_scan(negative, Association::kKnown, {}), std::invalid_argument);
  EXPECT_NO_THROW(plan_scan(negative, Association::kMaximumLikelihood, {}));
  const std::vector<Observation> repeated = {{1.0, 0.0, 4}, {2.0, 0.0, 4}};
  EXPECT_THROW(plan_scan(repeated, Association::kKnown, {}), std::invalid_argument);
  const std::vector<Observation> too_many(kLandmarkIdsPerScan, Observation{1.0, 0.0, -1});
  EXPECT_THROW(plan_scan(too_many, Association::kMaximumLikelihood, {}), std::invalid_argument);
}

TEST(ScanPlanTest, RefusesBadControls) {
  EXPECT_NO_THROW(check_control({1.0, 0.1}, 0.0));
  EXPECT_THROW(check_control({1.0, 0.1}, -0.1), std::invalid_argument);
  EXPECT_THROW(check_control({std::nan(""), 0.1}, 0.1), std::invalid_argument);
  EXPECT_THROW(check_control({1.0, 0.1}, std::numeric_limits<double>::infinity()),
               std::invalid_argument);
}

TEST(ScanPlanTest, MapCheckBoundsEveryLargestEigenvalue) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(0.01, 4.0);
  std::vector<MapLandmark> map;
  double oracle = 0.5;
  for (std::uint64_t k = 0; k < 30; ++k) {
    Eigen::Matrix2d a;
    a << u(rng), u(rng) - 2.0, u(rng) - 2.0, u(rng);
    const Eigen::Matrix2d cov = a * a.transpose() + 0.01 * Eigen::Matrix2d::Identity();
    map.push_back({0, 100 + k, u(rng), u(rng), cov(0, 0), cov(0, 1), cov(1, 1), 0.0, 0});
    oracle = std::max(oracle, Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(cov).eigenvalues()[1]);
  }
  const MapCheck checked = check_map(map, true, 0.5);
  EXPECT_NEAR(checked.variance_bound, oracle, 1e-12 * oracle);
  ASSERT_EQ(checked.known.size(), map.size());
  for (std::size_t k = 0; k < map.size(); ++k) EXPECT_EQ(checked.known.at(100 + k), k);
  map.push_back(map.front());
  EXPECT_THROW(check_map(map, true, 0.0), std::invalid_argument);
  EXPECT_NO_THROW(check_map(map, false, 0.0));
  map.back().sxy = 10.0;  // not positive definite
  EXPECT_THROW(check_map(map, false, 0.0), std::invalid_argument);
  map.back() = map.front();
  map.back().x = 1e151;
  EXPECT_THROW(check_map(map, false, 0.0), std::invalid_argument);
}

}  // namespace
}  // namespace fastslam::engine::internal
