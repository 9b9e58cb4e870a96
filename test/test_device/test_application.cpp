// The device application with a fake clock and recording motors: boot state, scenes,
// trials, the watchdog, STOP, direct PWM and bad input. Motors must never stay on when
// something goes wrong.
#include <gtest/gtest.h>

#include "common/hand_scenes.h"
#include "graspguide_device/application.h"
#include "graspguide_hal/fake_hal.h"

namespace gg = graspguide;
namespace gd = graspguide::device;
namespace gh = graspguide::hal;
using gg::Real;

constexpr uint32_t kMs = 1000;

gg::Scene<Real> hand_scene(int k = 4) {
  gg::Scene<Real> s;
  s.k = k;
  s.contacts = graspguide_test::nominal_hand().cast<Real>();
  return s;
}

gg::Vec6<Real> down() {  // a weight straight down the hand's -z: aligned at identity
  gg::Vec6<Real> w;
  w << 0, 0, -1, 0, 0, 0;
  return w;
}

gg::Vec6<Real> sideways() {
  gg::Vec6<Real> w;
  w << 0.4f, -1.0f, 0.3f, 0, 0, 0;
  return w;
}

gd::PoseIn pose_at(uint32_t t_us, Eigen::Vector4f q = Eigen::Vector4f(1, 0, 0, 0)) {
  gd::PoseIn p;
  p.host_time_us = t_us;
  p.quat_wxyz = q.cast<Real>();
  return p;
}

struct Rig {
  gh::FakeClock clock;
  gh::RecordingMotors motors;
  gd::Application app{motors, clock};
  gd::Telemetry tel;
  gd::TrialReport report;
  bool ended = false;
  gd::Reply send(const gd::PoseIn& p) { return app.pose(p, tel, report, ended); }
};

TEST(Application, MotorsAreOffAtBoot) {
  Rig r;
  EXPECT_EQ(r.motors.writes(), 1u);
  EXPECT_TRUE(r.motors.all_off());
  EXPECT_EQ(r.app.state(), gd::DeviceState::kIdle);
}

TEST(Application, PosesAndTrialsNeedAScene) {
  Rig r;
  EXPECT_EQ(r.send(pose_at(0)).refusal, gd::Refusal::kNoScene);
  EXPECT_EQ(r.app.start_trial(1, down()).refusal, gd::Refusal::kNoScene);
  EXPECT_TRUE(r.motors.all_off());
}

TEST(Application, AnInvalidSceneIsRefusedAndThePreviousOneKept) {
  Rig r;
  auto bad = hand_scene();
  bad.contacts.col(1) = bad.contacts.col(0);
  EXPECT_EQ(r.app.set_scene(bad).status, gg::Status::kCoincidentContacts);
  EXPECT_EQ(r.app.state(), gd::DeviceState::kIdle);
  ASSERT_TRUE(r.app.set_scene(hand_scene()).ok());
  auto collinear = hand_scene(3);
  collinear.contacts.col(1) =
      collinear.contacts.col(0) + 0.3f * (collinear.contacts.col(2) - collinear.contacts.col(0));
  EXPECT_EQ(r.app.set_scene(collinear).status, gg::Status::kRankDeficient);
  auto nan = hand_scene();
  nan.contacts(0, 0) = std::numeric_limits<Real>::quiet_NaN();
  EXPECT_EQ(r.app.set_scene(nan).status, gg::Status::kNonFiniteInput);
  EXPECT_TRUE(r.motors.all_off());
  // The valid scene is still the one used.
  ASSERT_TRUE(r.app.start_trial(7, sideways()).ok());
  ASSERT_TRUE(r.send(pose_at(0)).ok());
  const auto expect = graspguide_test::solve_once<Real>(hand_scene(), sideways().cast<double>(),
                                                        Eigen::Vector4d(1, 0, 0, 0));
  EXPECT_EQ(graspguide_test::max_pwm_diff(r.tel.pwm, expect.frame.pwm), 0);
  EXPECT_EQ(graspguide_test::max_pwm_diff(r.motors.last(), expect.frame.pwm), 0);
}

TEST(Application, ABadWrenchIsRefusedAtStart) {
  Rig r;
  ASSERT_TRUE(r.app.set_scene(hand_scene()).ok());
  EXPECT_EQ(r.app.start_trial(1, gg::Vec6<Real>::Zero()).status, gg::Status::kZeroWrench);
  gg::Vec6<Real> moment_only;
  moment_only << 0, 0, 0, 0, 0.1f, 0;
  EXPECT_EQ(r.app.start_trial(1, moment_only).status, gg::Status::kZeroForce);
  EXPECT_EQ(r.app.state(), gd::DeviceState::kSceneSet);
}

TEST(Application, TelemetryPwmEqualsTheCoreForEveryPose) {
  Rig r;
  auto scene = hand_scene();
  scene.mode = gg::Mode::kV;
  ASSERT_TRUE(r.app.set_scene(scene).ok());
  ASSERT_TRUE(r.app.start_trial(3, sideways()).ok());
  std::mt19937_64 rng(3);
  for (int n = 0; n < 50; ++n) {
    const auto rs = graspguide_test::random_scene(rng, 4);
    r.clock.advance_us(4 * kMs);
    ASSERT_TRUE(r.send(pose_at(n * 4 * kMs, rs.orientation.cast<float>())).ok());
    if (r.ended) break;
    const auto expect =
        graspguide_test::solve_once<Real>(scene, sideways().cast<double>(), rs.orientation);
    EXPECT_EQ(graspguide_test::max_pwm_diff(r.tel.pwm, expect.frame.pwm), 0) << n;
    EXPECT_NEAR(r.tel.error_deg, expect.frame.error_deg, 1e-4f);
    EXPECT_FALSE(r.tel.recomputed);  // fixed posture: the grasp was solved at START_TRIAL
  }
}

TEST(Application, ATrialSucceedsAfterTheHoldAndSwitchesTheMotorsOff) {
  Rig r;
  ASSERT_TRUE(r.app.set_scene(hand_scene()).ok());
  ASSERT_TRUE(r.app.start_trial(42, down()).ok());
  uint32_t t = 1'000'000;
  for (int n = 0; n < 200 && !r.ended; ++n, t += 4 * kMs) {
    ASSERT_TRUE(r.send(pose_at(t)).ok());
    if (!r.ended) {
      EXPECT_FALSE(r.motors.all_off());  // mode C: on until success
    }
  }
  ASSERT_TRUE(r.ended);
  EXPECT_EQ(r.report.trial_id, 42);
  EXPECT_TRUE(r.report.result.success);
  EXPECT_NEAR(r.report.result.completion_s, 0.5, 0.0041);
  EXPECT_TRUE(r.motors.all_off());
  EXPECT_EQ(r.app.state(), gd::DeviceState::kSceneSet);
  EXPECT_EQ(r.send(pose_at(t)).refusal, gd::Refusal::kNotAllowedInState);
  EXPECT_TRUE(r.motors.all_off());
}

TEST(Application, ATrialTimesOutAt90sAcrossA32BitWrap) {
  Rig r;
  ASSERT_TRUE(r.app.set_scene(hand_scene()).ok());
  ASSERT_TRUE(r.app.start_trial(9, sideways()).ok());
  const Eigen::Vector4f upside_down(0, 1, 0, 0);
  uint32_t t = 0xFFFFFFFFu - 30'000'000u;  // wraps 30 s into the trial
  for (int n = 0; n < 30000 && !r.ended; ++n, t += 4 * kMs)
    ASSERT_TRUE(r.send(pose_at(t, upside_down)).ok());
  ASSERT_TRUE(r.ended);
  EXPECT_FALSE(r.report.result.success);
  EXPECT_DOUBLE_EQ(r.report.result.completion_s, 90.0);
  EXPECT_TRUE(r.motors.all_off());
}

TEST(Application, TheWatchdogSwitchesTheMotorsOffWhenPosesStop) {
  Rig r;
  ASSERT_TRUE(r.app.set_scene(hand_scene()).ok());
  ASSERT_TRUE(r.app.start_trial(1, sideways()).ok());
  ASSERT_TRUE(r.send(pose_at(0)).ok());
  ASSERT_FALSE(r.motors.all_off());
  uint32_t latency_us = 0;
  for (uint32_t step = 0; step < 400; ++step) {  // 1 ms ticks
    r.clock.advance_us(kMs);
    r.app.tick();
    if (r.motors.all_off()) {
      latency_us = (step + 1) * kMs;
      break;
    }
  }
  EXPECT_EQ(latency_us, gd::kDefaultStaleTimeoutUs);  // off at the first tick at 200 ms
  EXPECT_EQ(r.app.counters().stale_events, 1u);
  for (int i = 0; i < 10; ++i) {
    r.clock.advance_us(50 * kMs);
    r.app.tick();
  }
  EXPECT_EQ(r.app.counters().stale_events, 1u);  // one event per silence
  ASSERT_TRUE(r.send(pose_at(700 * kMs)).ok());
  EXPECT_FALSE(r.motors.all_off());  // the stream is back
}

TEST(Application, StopActsAtOnceInEveryState) {
  Rig r;
  r.app.stop();
  EXPECT_TRUE(r.motors.all_off());
  EXPECT_EQ(r.app.state(), gd::DeviceState::kIdle);
  ASSERT_TRUE(r.app.set_scene(hand_scene()).ok());
  ASSERT_TRUE(r.app.start_trial(1, sideways()).ok());
  ASSERT_TRUE(r.send(pose_at(0)).ok());
  ASSERT_FALSE(r.motors.all_off());
  r.app.stop();
  EXPECT_TRUE(r.motors.all_off());
  EXPECT_EQ(r.app.state(), gd::DeviceState::kStopped);
  EXPECT_EQ(r.send(pose_at(4 * kMs)).refusal, gd::Refusal::kNotAllowedInState);
  EXPECT_TRUE(r.motors.all_off());
  ASSERT_TRUE(r.app.start_trial(2, sideways()).ok());  // the scene is kept
  ASSERT_TRUE(r.send(pose_at(8 * kMs)).ok());
  EXPECT_FALSE(r.motors.all_off());
}

TEST(Application, DirectPwmIsForCalibrationOnlyAndStillWatched) {
  Rig r;
  gg::Pwm pwm;
  pwm.duty[0] = 255;
  pwm.duty[2] = 70;
  ASSERT_TRUE(r.app.set_motors(pwm).ok());
  EXPECT_EQ(r.motors.last().duty[0], 255);
  r.clock.advance_us(gd::kDefaultStaleTimeoutUs);
  r.app.tick();
  EXPECT_TRUE(r.motors.all_off());
  ASSERT_TRUE(r.app.set_scene(hand_scene()).ok());
  ASSERT_TRUE(r.app.start_trial(1, sideways()).ok());
  EXPECT_EQ(r.app.set_motors(pwm).refusal, gd::Refusal::kNotAllowedInState);
}

TEST(Application, BadPosesTurnTheMotorsOffAndTheStreamRecovers) {
  Rig r;
  ASSERT_TRUE(r.app.set_scene(hand_scene()).ok());
  ASSERT_TRUE(r.app.start_trial(1, sideways()).ok());
  ASSERT_TRUE(r.send(pose_at(0)).ok());
  const gg::Pwm good = r.motors.last();
  auto nan = pose_at(4 * kMs);
  nan.quat_wxyz(2) = std::numeric_limits<Real>::quiet_NaN();
  EXPECT_EQ(r.send(nan).status, gg::Status::kNonFiniteInput);
  EXPECT_TRUE(r.motors.all_off());
  auto coincident = pose_at(8 * kMs);
  coincident.has_contacts = true;
  coincident.contacts = hand_scene().contacts;
  coincident.contacts.col(3) = coincident.contacts.col(2);
  EXPECT_EQ(r.send(coincident).status, gg::Status::kCoincidentContacts);
  EXPECT_TRUE(r.motors.all_off());
  // The next pose without contacts renders the last good posture again.
  ASSERT_TRUE(r.send(pose_at(12 * kMs)).ok());
  EXPECT_EQ(graspguide_test::max_pwm_diff(r.motors.last(), good), 0);
  EXPECT_EQ(r.send(pose_at(10 * kMs)).status, gg::Status::kTimeWentBackwards);
  EXPECT_TRUE(r.motors.all_off());
  EXPECT_EQ(r.app.last_error(), gg::Status::kTimeWentBackwards);
}

TEST(Application, MovingContactsRecomputeTheGrasp) {
  Rig r;
  ASSERT_TRUE(r.app.set_scene(hand_scene()).ok());
  ASSERT_TRUE(r.app.start_trial(1, sideways()).ok());
  auto p = pose_at(0);
  p.has_contacts = true;
  p.contacts = hand_scene().contacts;
  ASSERT_TRUE(r.send(p).ok());
  EXPECT_FALSE(r.tel.recomputed);  // the same posture as the scene's
  p.contacts(1, 2) += 0.01f;
  p.host_time_us = 4 * kMs;
  ASSERT_TRUE(r.send(p).ok());
  EXPECT_TRUE(r.tel.recomputed);
}
