// InnovationStats against the chi-square law it tests: its points, sampled distances (the
// Mahalanobis distances of 2-D Gaussian innovations under their own covariance), the counting of
// outcomes and non-finite distances, the warning's threshold and the checkpoint state.
#include "tools/eval/innovation_stats.h"

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace fastslam::tools {
namespace {

using engine::AssociationOutcome;
using engine::ObservationAssociation;

ObservationAssociation associated(double m2) { return {0, AssociationOutcome::kAssociated, 1, m2}; }

TEST(InnovationStatsTest, PointsAreTheChiSquareTwoUpperTails) {
  for (const InnovationStats::Point& p : InnovationStats::kPoints) {
    // Two degrees of freedom: P(X > x) = exp(-x / 2).
    EXPECT_NEAR(std::exp(-p.bound / 2.0), p.tail, 1e-15);
  }
}

// Innovations v ~ N(0, S) for random covariances S, scored v^T S^-1 v: the fractions beyond each
// point and the mean fall within 5 standard errors of the law's (0.5 / 0.05 / 0.01, mean 2 with
// variance 4), so a wrong point or a wrong count fails and the test does not flake.
TEST(InnovationStatsTest, ConsistentInnovationsMatchTheLaw) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> uniform(0.1, 3.0);
  InnovationStats stats;
  constexpr int kScans = 40000;
  constexpr int kPerScan = 5;
  for (int s = 0; s < kScans; ++s) {
    std::vector<ObservationAssociation> scan;
    for (int j = 0; j < kPerScan; ++j) {
      // S = L L^T with L lower triangular; v = L n, so v^T S^-1 v = |n|^2 computed the long way.
      const double l00 = uniform(rng), l10 = uniform(rng) - 1.5, l11 = uniform(rng);
      const double n0 = normal(rng), n1 = normal(rng);
      const double v0 = l00 * n0, v1 = l10 * n0 + l11 * n1;
      const double s00 = l00 * l00, s01 = l00 * l10, s11 = l10 * l10 + l11 * l11;
      const double det = s00 * s11 - s01 * s01;
      const double m2 = (s11 * v0 * v0 - 2.0 * s01 * v0 * v1 + s00 * v1 * v1) / det;
      scan.push_back(associated(m2));
    }
    stats.add(scan);
  }
  const double n = kScans * kPerScan;
  ASSERT_EQ(stats.associated(), static_cast<std::uint64_t>(n));
  for (std::size_t k = 0; k < InnovationStats::kPoints.size(); ++k) {
    const double p = InnovationStats::kPoints[k].tail;
    EXPECT_NEAR(stats.beyond(k), p, 5.0 * std::sqrt(p * (1.0 - p) / n)) << k;
  }
  EXPECT_NEAR(stats.mean(), 2.0, 5.0 * 2.0 / std::sqrt(n));
  EXPECT_FALSE(stats.warning().has_value());
}

// Innovations twice as wide as the model (covariance 4 S scored with S) put about 31 % beyond
// the 99 % point (exp(-9.21 / 8)) and the mean near 8: the warning names the fraction and the fix.
TEST(InnovationStatsTest, WideInnovationsWarn) {
  std::mt19937_64 rng(11);
  std::normal_distribution<double> normal;
  InnovationStats stats;
  for (int s = 0; s < 20000; ++s) {
    const double n0 = 2.0 * normal(rng), n1 = 2.0 * normal(rng);
    const std::vector<ObservationAssociation> scan = {associated(n0 * n0 + n1 * n1)};
    stats.add(scan);
  }
  EXPECT_NEAR(stats.beyond(2), std::exp(-9.2103403719761836 / 8.0), 0.01);
  EXPECT_NEAR(stats.mean(), 8.0, 0.25);
  const std::optional<std::string> warning = stats.warning();
  ASSERT_TRUE(warning.has_value());
  EXPECT_NE(warning->find("beyond its 99% bound"), std::string::npos) << *warning;
  EXPECT_NE(warning->find("--sigma-range"), std::string::npos) << *warning;
}

TEST(InnovationStatsTest, CountsOutcomesAndNonFiniteDistances) {
  InnovationStats stats;
  const std::vector<ObservationAssociation> scan = {
      associated(1.0),
      associated(std::numeric_limits<double>::infinity()),
      associated(std::numeric_limits<double>::quiet_NaN()),
      associated(6.0),
      {4, AssociationOutcome::kNew, 7, std::numeric_limits<double>::infinity()},
      {5, AssociationOutcome::kDiscarded, 0, 8.0},
  };
  stats.add(scan);
  EXPECT_EQ(stats.associated(), 4u);
  EXPECT_EQ(stats.started(), 1u);
  EXPECT_EQ(stats.discarded(), 1u);
  EXPECT_DOUBLE_EQ(stats.mean(), 3.5);      // the finite ones: (1 + 6) / 2
  EXPECT_DOUBLE_EQ(stats.beyond(0), 0.75);  // 6, inf, NaN beyond 1.39
  EXPECT_DOUBLE_EQ(stats.beyond(1), 0.75);  // 6 > 5.99
  EXPECT_DOUBLE_EQ(stats.beyond(2), 0.5);   // inf, NaN
}

TEST(InnovationStatsTest, WarnsOnlyWithEnoughAssociationsAndFromFiveTimesTheTail) {
  auto with = [](int inside, int outside) {
    InnovationStats stats;
    std::vector<ObservationAssociation> scan(static_cast<std::size_t>(inside), associated(1.0));
    scan.insert(scan.end(), static_cast<std::size_t>(outside), associated(20.0));
    stats.add(scan);
    return stats;
  };
  EXPECT_FALSE(with(0, 99).warning().has_value());  // below kMinimum
  EXPECT_TRUE(with(0, 100).warning().has_value());
  EXPECT_TRUE(with(950, 50).warning().has_value());   // 5.0 %
  EXPECT_FALSE(with(951, 49).warning().has_value());  // 4.9 %
}

// since(): what the later scans added, as if counted alone (the mean from the difference of
// the running sums, to rounding).
TEST(InnovationStatsTest, SinceIsWhatTheLaterScansAdded) {
  const std::vector<ObservationAssociation> early = {
      associated(0.5), associated(12.0), {1, AssociationOutcome::kNew, 3, 0.0}};
  const std::vector<ObservationAssociation> late = {
      associated(2.0),
      associated(7.0),
      associated(std::numeric_limits<double>::infinity()),
      {3, AssociationOutcome::kNew, 4, 0.0},
      {4, AssociationOutcome::kDiscarded, 0, 1.0}};
  InnovationStats run;
  run.add(early);
  const InnovationStats at_row = run;
  run.add(late);
  InnovationStats alone;
  alone.add(late);
  const InnovationStats since = run.since(at_row);
  EXPECT_EQ(since.associated(), alone.associated());
  EXPECT_EQ(since.started(), alone.started());
  EXPECT_EQ(since.discarded(), alone.discarded());
  for (std::size_t k = 0; k < InnovationStats::kPoints.size(); ++k) {
    EXPECT_EQ(since.beyond(k), alone.beyond(k)) << k;
  }
  EXPECT_NEAR(since.mean(), alone.mean(), 1e-12);
  EXPECT_TRUE(std::isnan(run.since(run).mean()));
  EXPECT_EQ(run.since(run).started(), 0u);
}

TEST(InnovationStatsTest, EmptyReportsNull) {
  const InnovationStats stats;
  EXPECT_TRUE(std::isnan(stats.mean()));
  EXPECT_TRUE(std::isnan(stats.beyond(0)));
  const nlohmann::json m = stats.metrics();
  EXPECT_TRUE(m["nis_mean"].is_null());
  EXPECT_TRUE(m["beyond_chi2_99"].is_null());
  EXPECT_EQ(m["associated"], 0);
  EXPECT_FALSE(stats.warning().has_value());
}

// A checkpoint's state brings back the same metrics, the mean's bits included, through JSON text.
TEST(InnovationStatsTest, StateRoundTripsExactly) {
  InnovationStats stats;
  const std::vector<ObservationAssociation> scan = {associated(0.1),
                                                    associated(1.0 / 3.0),
                                                    associated(7.7),
                                                    {3, AssociationOutcome::kNew, 9, 0.0}};
  for (int k = 0; k < 3; ++k) stats.add(scan);
  const std::string text = stats.state().dump();
  const InnovationStats back = InnovationStats::from_state(nlohmann::json::parse(text));
  EXPECT_EQ(back.metrics(), stats.metrics());
  EXPECT_EQ(back.mean(), stats.mean());
  EXPECT_EQ(back.state(), stats.state());
  EXPECT_THROW(InnovationStats::from_state(nlohmann::json::parse(R"({"associated": 1})")),
               nlohmann::json::exception);
}

}  // namespace
}  // namespace fastslam::tools
