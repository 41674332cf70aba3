// The resampling stage: each particle's FastSLAM 2.0 no-odometry covariance must follow it to
// its descendants (the particle's x identifies its ancestor, an oracle independent of the
// resampler's internals), other configurations leave the covariances alone; the evidence adds
// ln sum w; an impossible scan resets the weights; a NaN weight is a runtime_error.
#include "engine/internal/resample_stage.h"

#include <cmath>
#include <limits>
#include <stdexcept>

#include <gtest/gtest.h>

namespace fastslam::engine::internal {
namespace {

FilterConfig config(Algorithm algorithm, MotionKind motion) {
  FilterConfig c;
  c.algorithm = algorithm;
  c.motion.kind = motion;
  c.particles = 64;
  c.threads = 2;
  c.resample.when = parallel::ResamplePolicy::When::kEveryStep;
  return c;
}

void spread(FilterState& s) {
  for (std::size_t i = 0; i < s.store.size(); ++i) {
    s.store.x()[i] = static_cast<double>(i);
    // Weights concentrated on a few particles, so that resampling duplicates them.
    s.store.log_weight()[i] = i % 9 == 0 ? 0.0 : -5.0;
    if (!s.covariances.values().empty()) {
      s.covariances.at<5>(i).setConstant(static_cast<double>(i) + 0.5);
    }
  }
}

TEST(ResampleStageTest, CovariancesFollowTheirParticlesWithoutOdometry) {
  const FilterConfig c = config(Algorithm::kFastSlam2, MotionKind::kBrownian);
  parallel::ParticleKernel kernel({c.threads, c.grain});
  FilterState s(c);
  ResampleStage stage(c, kernel);
  spread(s);
  double log_sum = 0.0;
  for (std::size_t i = 0; i < s.store.size(); ++i) log_sum += std::exp(s.store.log_weight()[i]);
  stage.run(s, 5, false);
  EXPECT_EQ(s.counters.resamples, 1u);
  EXPECT_NEAR(s.counters.log_evidence, std::log(log_sum), 1e-12);
  bool duplicated = false;
  for (std::size_t i = 0; i < s.store.size(); ++i) {
    const double ancestor = s.store.x()[i];
    duplicated |= ancestor != static_cast<double>(i);
    EXPECT_EQ(s.covariances.at<5>(i)(3, 4), ancestor + 0.5) << i;
  }
  EXPECT_TRUE(duplicated);
}

TEST(ResampleStageTest, OtherConfigurationsLeaveTheCovariances) {
  // FastSLAM 2.0 with odometry restarts the covariances at every control; FastSLAM 1.0 keeps none.
  for (const FilterConfig& c : {config(Algorithm::kFastSlam2, MotionKind::kBaileyCar),
                                config(Algorithm::kFastSlam1, MotionKind::kBrownian)}) {
    parallel::ParticleKernel kernel({c.threads, c.grain});
    FilterState s(c);
    ResampleStage stage(c, kernel);
    spread(s);
    stage.run(s, 5, true);
    EXPECT_EQ(s.counters.resamples, 1u);
    if (c.algorithm == Algorithm::kFastSlam1) {
      EXPECT_TRUE(s.covariances.values().empty());
      continue;
    }
    for (std::size_t i = 0; i < s.store.size(); ++i) {
      EXPECT_EQ(s.covariances.at<5>(i)(0, 0), static_cast<double>(i) + 0.5);
    }
  }
}

TEST(ResampleStageTest, ImpossibleScanResetsNanFails) {
  const FilterConfig c = config(Algorithm::kFastSlam1, MotionKind::kBaileyCar);
  parallel::ParticleKernel kernel({c.threads, c.grain});
  FilterState s(c);
  ResampleStage stage(c, kernel);
  for (double& l : s.store.log_weight()) l = -std::numeric_limits<double>::infinity();
  stage.run(s, 3, false);
  EXPECT_EQ(s.counters.weight_resets, 1u);
  EXPECT_EQ(s.counters.log_evidence, -std::numeric_limits<double>::infinity());
  for (double l : s.store.log_weight()) EXPECT_EQ(l, -std::log(64.0));
  s.store.log_weight()[7] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(stage.run(s, 4, false), std::runtime_error);
}

}  // namespace
}  // namespace fastslam::engine::internal
