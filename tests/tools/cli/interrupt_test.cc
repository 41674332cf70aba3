#include "tools/cli/interrupt.h"

#include <csignal>

#include <gtest/gtest.h>

namespace fastslam::tools {
namespace {

TEST(Interrupt, TheFirstSignalOnlySetsTheFlag) {
  for (const int signal : {SIGINT, SIGTERM}) {
    {
      const InterruptHandlers handlers;
      EXPECT_EQ(interrupt_signal(), 0);
      ASSERT_EQ(std::raise(signal), 0);  // the process goes on
      EXPECT_EQ(interrupt_signal(), signal);
    }
    // Cleared for whoever runs next without handlers.
    EXPECT_EQ(interrupt_signal(), 0);
  }
  EXPECT_STREQ(interrupt_name(SIGINT), "SIGINT");
  EXPECT_STREQ(interrupt_name(SIGTERM), "SIGTERM");
}

TEST(Interrupt, TheSecondSignalEndsTheProcess) {
  EXPECT_EXIT(
      {
        const InterruptHandlers handlers;
        std::raise(SIGINT);
        std::raise(SIGINT);
        std::_Exit(0);  // not reached
      },
      ::testing::KilledBySignal(SIGINT), "");
}

TEST(Interrupt, HandlersAreRestoredAndIgnoredSignalsStayIgnored) {
  const auto previous = std::signal(SIGTERM, SIG_IGN);
  {
    const InterruptHandlers handlers;
    ASSERT_EQ(std::raise(SIGTERM), 0);
    EXPECT_EQ(interrupt_signal(), 0);  // ignored, as the parent asked
  }
  EXPECT_EQ(std::signal(SIGTERM, previous), SIG_IGN);
  const auto before = std::signal(SIGINT, SIG_DFL);
  { const InterruptHandlers handlers; }
  EXPECT_EQ(std::signal(SIGINT, before), SIG_DFL);
}

}  // namespace
}  // namespace fastslam::tools
