#include "tools/cli/progress.h"

#include <cstdio>
#include <string>

#include <gtest/gtest.h>

namespace fastslam::tools {
namespace {

TEST(Progress, FormatsStepsRateEtaParticlesLandmarksAndMemory) {
  ProgressState s;
  s.done = 2500;
  s.total = 10000;
  s.particles = 100;
  s.landmarks = 1234;
  s.map_bytes = 5 * 1024 * 1024;
  // 2500 steps in 2 s: 1250 steps/s, 7500 left: 6 s.
  const std::string line = format_progress(s, 2.0, 20);
  EXPECT_EQ(line,
            "[#####...............]  25.0%  2.5k/10k steps  1.25k steps/s  ETA 0:06  M 100  "
            "1.23k landmarks  5.0 MB")
      << line;
}

TEST(Progress, UnknownTotalHasNoBarAndLongEtaHasHours) {
  ProgressState s;
  s.done = 12;
  s.particles = 1;
  EXPECT_EQ(format_progress(s, 4.0), "12 steps  3 steps/s  M 1  0 landmarks  0.0 kB");
  s.total = 3600 * 3 + 12;
  s.done = 12;
  // 3 steps/s, 10800 steps left: one hour.
  EXPECT_NE(format_progress(s, 4.0).find("ETA 1:00:00"), std::string::npos);
  s.done = s.total + 5;  // more than expected: a full bar, no negative ETA
  const std::string over = format_progress(s, 4.0, 4);
  EXPECT_EQ(over.rfind("[####] 100.0%", 0), 0u) << over;
  EXPECT_NE(over.find("ETA ?"), std::string::npos) << over;
}

TEST(Progress, QuietWhenNotATerminal) {
  std::FILE* file = std::tmpfile();
  ASSERT_NE(file, nullptr);
  ProgressBar bar(true, file);
  EXPECT_FALSE(bar.enabled());
  EXPECT_FALSE(bar.due());
  bar.draw(ProgressState{});
  bar.finish(ProgressState{});
  EXPECT_EQ(std::ftell(file), 0);
  std::fclose(file);
  EXPECT_FALSE(ProgressBar(false).enabled());
}

}  // namespace
}  // namespace fastslam::tools
