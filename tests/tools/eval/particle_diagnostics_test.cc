#include "tools/eval/particle_diagnostics.h"

#include <cmath>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

namespace fastslam::tools {
namespace {

// Four particles by hand: two copies at (0, 0) (a resampled survivor), one at (2, 0), one at
// (0, 2); weights 1/2, 1/4, 1/4 across the three positions (log-weights shifted by a constant,
// which must not matter).
TEST(ParticleDiagnostics, HandComputedSet) {
  const std::vector<double> x = {0, 0, 2, 0}, y = {0, 0, 0, 2};
  const double c = -1000.0;
  const std::vector<double> lw = {c + std::log(0.25), c + std::log(0.25), c + std::log(0.25),
                                  c + std::log(0.25)};
  const ParticleDiagnostics d = diagnose_particles(x, y, lw, StampedPose{0, 2.0, 0.5, 0});
  EXPECT_NEAR(d.effective_sample_size, 4.0, 1e-12);
  EXPECT_EQ(d.distinct, 3u);
  // Mean (0.5, 0.5); squared distances 0.5, 0.5, 2.5, 2.5 at weight 1/4 each: variance 1.5.
  EXPECT_NEAR(d.spread, std::sqrt(1.5), 1e-12);
  ASSERT_TRUE(d.truth_spreads.has_value());
  EXPECT_NEAR(*d.truth_spreads, std::hypot(1.5, 0.0) / std::sqrt(1.5), 1e-12);
  ASSERT_TRUE(d.nearest_weight.has_value());
  EXPECT_NEAR(*d.nearest_weight, 1.0, 1e-12);  // (2, 0), weight 1/4 of 4 particles
}

TEST(ParticleDiagnostics, DepletedSetAndUnevenWeights) {
  const std::vector<double> x = {1, 1, 1}, y = {5, 5, 5};
  const std::vector<double> lw = {0.0, std::log(2.0), -std::numeric_limits<double>::infinity()};
  const ParticleDiagnostics d = diagnose_particles(x, y, lw, std::nullopt);
  EXPECT_NEAR(d.effective_sample_size, 1.0 / (1.0 / 9 + 4.0 / 9), 1e-12);
  EXPECT_EQ(d.distinct, 1u);
  EXPECT_EQ(d.spread, 0.0);
  EXPECT_FALSE(d.truth_spreads.has_value());
  EXPECT_FALSE(d.nearest_weight.has_value());
  // With a truth but no spread: no spreads, the nearest weight still.
  const ParticleDiagnostics t = diagnose_particles(x, y, lw, StampedPose{0, 0, 0, 0});
  EXPECT_FALSE(t.truth_spreads.has_value());
  EXPECT_NEAR(*t.nearest_weight, 3.0 / 3.0, 1e-12);  // the first nearest: weight 1/3, M = 3
}

TEST(ParticleDiagnostics, RefusesUnusableInput) {
  const std::vector<double> one = {0.0}, two = {0.0, 1.0};
  EXPECT_THROW(diagnose_particles({}, {}, {}, std::nullopt), std::invalid_argument);
  EXPECT_THROW(diagnose_particles(one, two, one, std::nullopt), std::invalid_argument);
  const std::vector<double> dead = {-std::numeric_limits<double>::infinity()};
  EXPECT_THROW(diagnose_particles(one, one, dead, std::nullopt), std::invalid_argument);
}

}  // namespace
}  // namespace fastslam::tools
