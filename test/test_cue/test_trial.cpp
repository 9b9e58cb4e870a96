// The trial state machine on injected timestamps: hold, broken holds, timeout, bad input.
#include <gtest/gtest.h>

#include "graspguide_cue/trial.h"

namespace gg = graspguide;

constexpr int64_t kMs = 1000;

gg::Trial started(int64_t t0 = 5 * kMs) {
  gg::Trial t;
  EXPECT_EQ(t.start(gg::TrialConfig{}, t0), gg::Status::kOk);
  return t;
}

TEST(Trial, SucceedsWhenTheErrorStaysWithinTheThresholdForTheHoldTime) {
  gg::Trial t = started(0);
  EXPECT_EQ(t.update(100 * kMs, 20.0), gg::Status::kOk);
  EXPECT_EQ(t.update(1000 * kMs, 3.0), gg::Status::kOk);  // 3 deg counts as within
  EXPECT_TRUE(t.running());
  EXPECT_EQ(t.update(1499 * kMs, 2.0), gg::Status::kOk);
  EXPECT_TRUE(t.running());
  EXPECT_EQ(t.update(1500 * kMs, 2.5), gg::Status::kOk);  // exactly 0.5 s after entry
  EXPECT_EQ(t.state(), gg::TrialState::kSucceeded);
  EXPECT_TRUE(t.result().success);
  EXPECT_DOUBLE_EQ(t.result().completion_s, 1.5);
  EXPECT_DOUBLE_EQ(t.result().first_entry_s, 1.0);
  EXPECT_DOUBLE_EQ(t.result().final_error_deg, 2.5);
}

TEST(Trial, LeavingTheThresholdRestartsTheHold) {
  gg::Trial t = started(0);
  t.update(1000 * kMs, 1.0);
  t.update(1400 * kMs, 3.2);  // out again before 0.5 s
  t.update(1450 * kMs, 1.0);  // re-entry
  t.update(1900 * kMs, 1.0);
  EXPECT_TRUE(t.running());
  t.update(1950 * kMs, 1.0);
  EXPECT_EQ(t.state(), gg::TrialState::kSucceeded);
  EXPECT_DOUBLE_EQ(t.result().completion_s, 1.95);
  EXPECT_DOUBLE_EQ(t.result().first_entry_s, 1.0);  // the first entry is kept
}

TEST(Trial, FailsAtTheTimeoutAndReportsExactlyTheTimeout) {
  gg::Trial t = started(10 * kMs);
  for (int64_t ms = 10; ms <= 90'020; ms += 4) {
    t.update(ms * kMs, 45.0);
    if (!t.running()) break;
  }
  EXPECT_EQ(t.state(), gg::TrialState::kFailed);
  EXPECT_FALSE(t.result().success);
  EXPECT_DOUBLE_EQ(t.result().completion_s, 90.0);
  EXPECT_LT(t.result().first_entry_s, 0);  // never within the threshold
}

TEST(Trial, AHoldThatEndsAfterTheTimeoutIsAFailure) {
  gg::Trial t = started(0);
  t.update(89'800 * kMs, 1.0);
  t.update(90'300 * kMs, 1.0);  // the hold completes, but only after 90 s
  EXPECT_EQ(t.state(), gg::TrialState::kFailed);
  EXPECT_DOUBLE_EQ(t.result().completion_s, 90.0);
  EXPECT_DOUBLE_EQ(t.result().first_entry_s, 89.8);
}

TEST(Trial, BadInputLeavesTheStateUnchanged) {
  gg::Trial t = started(1000 * kMs);
  EXPECT_EQ(t.update(2000 * kMs, 1.0), gg::Status::kOk);
  EXPECT_EQ(t.update(1500 * kMs, 1.0), gg::Status::kTimeWentBackwards);
  EXPECT_EQ(t.update(2100 * kMs, std::numeric_limits<double>::quiet_NaN()),
            gg::Status::kNonFiniteInput);
  EXPECT_TRUE(t.running());
  EXPECT_EQ(t.update(2500 * kMs, 1.0), gg::Status::kOk);
  EXPECT_EQ(t.state(), gg::TrialState::kSucceeded);
}

TEST(Trial, ConfigurationIsValidated) {
  gg::Trial t;
  gg::TrialConfig c;
  c.hold_s = -1;
  EXPECT_EQ(t.start(c, 0), gg::Status::kBadConfig);
  c = gg::TrialConfig{};
  c.timeout_s = 0;
  EXPECT_EQ(t.start(c, 0), gg::Status::kBadConfig);
  c = gg::TrialConfig{};
  c.threshold_deg = std::numeric_limits<double>::infinity();
  EXPECT_EQ(t.start(c, 0), gg::Status::kBadConfig);
  EXPECT_EQ(t.state(), gg::TrialState::kIdle);
  EXPECT_EQ(t.update(10, 0.0), gg::Status::kOk);  // updates before a start do nothing
  EXPECT_EQ(t.state(), gg::TrialState::kIdle);
}

// Values that once passed (the limit was 1e30) and overflowed the int64 microseconds.
TEST(Trial, EveryFieldHasARangeAndTheOffenderIsNamed) {
  struct Case {
    double threshold_deg, hold_s, timeout_s;
    gg::TrialField bad;
  } cases[] = {
      {3, 0.5, 9.3e12, gg::TrialField::kTimeoutS},
      {3, 9.3e12, 90, gg::TrialField::kHoldS},
      {3, 0.5, 1800.001, gg::TrialField::kTimeoutS},
      {3, 600.001, 1800, gg::TrialField::kHoldS},
      {3, 91, 90, gg::TrialField::kHoldS},  // could never be held before the timeout
      {180.001, 0.5, 90, gg::TrialField::kThresholdDeg},
      {-0.001, 0.5, 90, gg::TrialField::kThresholdDeg},
      {3, -0.001, 90, gg::TrialField::kHoldS},
      {3, 0.5, 0, gg::TrialField::kTimeoutS},
      {std::numeric_limits<double>::quiet_NaN(), 0.5, 90, gg::TrialField::kThresholdDeg},
      {3, std::numeric_limits<double>::quiet_NaN(), 90, gg::TrialField::kHoldS},
      {3, 0.5, std::numeric_limits<double>::infinity(), gg::TrialField::kTimeoutS},
  };
  for (const Case& c : cases) {
    gg::TrialConfig cfg{c.threshold_deg, c.hold_s, c.timeout_s};
    gg::TrialField bad = gg::TrialField::kNone;
    EXPECT_EQ(gg::validate_trial_config(cfg, &bad), gg::Status::kBadConfig) << c.timeout_s;
    EXPECT_EQ(int(bad), int(c.bad)) << gg::trial_field_range(c.bad).key;
    gg::Trial t;
    EXPECT_EQ(t.start(cfg, 0), gg::Status::kBadConfig);
    EXPECT_FALSE(t.running());
  }
  // The edges themselves are accepted, and the longest trial still ends at its timeout.
  gg::TrialConfig edge{180, 600, 1800};
  gg::TrialField bad = gg::TrialField::kThresholdDeg;
  EXPECT_EQ(gg::validate_trial_config(edge, &bad), gg::Status::kOk);
  EXPECT_EQ(int(bad), int(gg::TrialField::kNone));
  gg::Trial t;
  ASSERT_EQ(t.start(gg::TrialConfig{0, 0, 1800}, 0), gg::Status::kOk);
  EXPECT_EQ(t.update(1799999999, 1.0), gg::Status::kOk);
  EXPECT_TRUE(t.running());
  EXPECT_EQ(t.update(1800000000, 1.0), gg::Status::kOk);
  EXPECT_EQ(t.state(), gg::TrialState::kFailed);
  EXPECT_DOUBLE_EQ(t.result().completion_s, 1800.0);
}

TEST(Trial, ExpireEndsARunningTrialAsTimedOut) {
  gg::Trial t;
  t.expire();  // nothing running: nothing happens
  EXPECT_EQ(t.state(), gg::TrialState::kIdle);
  ASSERT_EQ(t.start(gg::TrialConfig{}, 1000), gg::Status::kOk);
  t.update(2000, 1.0);
  t.expire();
  EXPECT_EQ(t.state(), gg::TrialState::kFailed);
  EXPECT_DOUBLE_EQ(t.result().completion_s, 90.0);
  EXPECT_DOUBLE_EQ(t.result().final_error_deg, 1.0);
}

TEST(Trial, CustomThresholdHoldAndTimeoutAndAbort) {
  gg::Trial t;
  gg::TrialConfig c;
  c.threshold_deg = 10;
  c.hold_s = 0;
  c.timeout_s = 5;
  ASSERT_EQ(t.start(c, 0), gg::Status::kOk);
  t.update(100 * kMs, 9.9);  // zero hold: the first sample within ends it
  EXPECT_EQ(t.state(), gg::TrialState::kSucceeded);
  ASSERT_EQ(t.start(c, 0), gg::Status::kOk);  // a finished trial can be started again
  t.abort();
  EXPECT_EQ(t.state(), gg::TrialState::kIdle);
  EXPECT_EQ(t.update(200 * kMs, 0.0), gg::Status::kOk);
  EXPECT_EQ(t.state(), gg::TrialState::kIdle);
}
