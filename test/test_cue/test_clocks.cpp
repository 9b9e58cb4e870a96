// The device's clocks: the pose watchdog, the host timeline and the trial's own deadline,
// across the wraps of their 32-bit counters.
#include <gtest/gtest.h>

#include "graspguide_cue/trial_clock.h"
#include "graspguide_cue/watchdog.h"

namespace gg = graspguide;

namespace {

TEST(PoseWatchdog, ExpiresAtTheTimeoutAndAPoseRestartsIt) {
  gg::PoseWatchdog w(200);
  w.feed(1000);
  EXPECT_FALSE(w.expired(1000));
  EXPECT_FALSE(w.expired(1199));
  EXPECT_TRUE(w.expired(1200));
  EXPECT_TRUE(w.expired(5000));
  w.feed(5000);
  EXPECT_FALSE(w.expired(5100));
  EXPECT_EQ(w.timeout(), 200u);
}

// millis() wraps after 49.7 days, micros() after 71.6 min: the same arithmetic.
TEST(PoseWatchdog, SurvivesTheWrapOfA32BitMillisecondClock) {
  gg::PoseWatchdog w(200);
  w.feed(0xFFFFFFF0u);  // 16 ms before the wrap
  EXPECT_FALSE(w.expired(0xFFFFFFFFu));
  EXPECT_FALSE(w.expired(183u));  // 199 ms later, past the wrap
  EXPECT_TRUE(w.expired(184u));   // exactly 200 ms later
  w.feed(0xFFFFFF00u);
  EXPECT_TRUE(w.expired(55u));  // 311 ms later
}

TEST(HostTimeline, AWrapIsASmallStepForwardAndAHugeStepForwardIsAStepBack) {
  gg::HostTimeline t;
  EXPECT_EQ(t.restart(0xFFFFFF00u), int64_t(0xFFFFFF00u));
  const int64_t after_wrap = t.advance(0x00000100u);
  EXPECT_EQ(after_wrap, int64_t(0xFFFFFF00u) + 0x200);
  EXPECT_LT(t.advance(0x00000100u + 0x80000000u), after_wrap);  // 2^31 us on reads as back
  gg::HostTimeline u;
  u.restart(5000);
  EXPECT_EQ(u.advance(4000), 4000);  // a step back stays a step back
}

TEST(TrialDeadline, PassesAtTimeoutPlusSlackOnTheDeviceClockAcrossItsWrap) {
  gg::TrialDeadline d;
  const uint32_t start = 0xFFFFF000u;  // the device's micros() is about to wrap
  d.start(start, 2.0, 1000000);
  EXPECT_FALSE(d.passed(start + 1000000u));
  EXPECT_FALSE(d.passed(start + 2999999u));  // wrapped, 2.999999 s later
  EXPECT_TRUE(d.passed(start + 3000000u));
  gg::TrialDeadline back;
  back.start(10000, 1.0, 0);
  EXPECT_FALSE(back.passed(9000));     // a virtual clock stepped back a little
  EXPECT_FALSE(back.passed(1009999));  // so 1 ms more is needed
  EXPECT_TRUE(back.passed(1010000));
}

}  // namespace
