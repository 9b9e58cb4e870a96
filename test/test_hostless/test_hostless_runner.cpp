// The host-less runner on fakes: a plan uploaded and checked, trials started by the button
// after the rest and the ready pattern, guided from IMU samples, ended by success or
// timeout, each appended to the results log before the next begins; IMU faults, a full
// log and a power cut. The IMU samples are built from the force direction an independent
// Guidance solve gives, so "aligned" and "off by 40 degrees" are known without the runner.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <vector>

#include "common/hand_scenes.h"
#include "graspguide_device/fake_storage.h"
#include "graspguide_device/hostless_app.h"
#include "graspguide_hal/fake_hal.h"

namespace gg = graspguide;
namespace gd = graspguide::device;
namespace gh = graspguide::hal;
using gg::Real;

namespace {

constexpr uint32_t kMs = 1000;
constexpr uint32_t kSamplePeriodUs = 10 * kMs;  // 100 Hz
constexpr float kG = 9.80665f;
constexpr float kAccelFs = 8 * kG;
constexpr float kGyroFs = 34.9f;

gd::PlanHeader header(uint16_t trials) {
  gd::PlanHeader h;
  std::strcpy(h.participant, "U1");
  h.simulated = true;
  h.trial_count = trials;
  h.threshold_deg = 3;
  h.hold_s = 0.5f;
  h.timeout_s = 5;
  h.rest_s = 1;
  const auto c = graspguide_test::nominal_hand();
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) {
      if (i < 3) h.hand_k3[i][j] = float(c(j, i));
      h.hand_k4[i][j] = float(c(j, i));
    }
  return h;
}

gd::PlanTrial trial(uint16_t index, uint8_t k, const float (&w)[6]) {
  gd::PlanTrial t;
  t.trial_index = index;
  t.session = 1;
  t.session_trial = uint8_t(index);
  t.k = k;
  t.wrench_number = uint8_t(index);
  std::memcpy(t.wrench, w, sizeof t.wrench);
  return t;
}

constexpr float kSideways[6] = {0.4f, -1.0f, 0.3f, 0, 0, 0};
constexpr float kOther[6] = {-0.6f, 0.2f, -0.7f, 0, 0, 0};

// The unit force direction in the hand frame of a trial, solved independently of the runner.
Eigen::Vector3d force_direction(const gd::PlanHeader& h, const gd::PlanTrial& t) {
  gg::Scene<Real> s;
  s.k = t.k;
  s.contacts.setZero();
  for (int i = 0; i < t.k; ++i)
    for (int j = 0; j < 3; ++j) s.contacts(j, i) = t.k == 3 ? h.hand_k3[i][j] : h.hand_k4[i][j];
  gg::Guidance<Real> g;
  gg::Vec6<Real> w;
  for (int j = 0; j < 6; ++j) w(j) = t.wrench[j];
  EXPECT_EQ(g.set_scene(s), gg::Status::kOk);
  EXPECT_EQ(g.set_wrench(w), gg::Status::kOk);
  gg::FrameResult<Real> f;
  EXPECT_EQ(g.update(Eigen::Matrix<Real, 4, 1>(1, 0, 0, 0), f), gg::Status::kOk);
  return g.grasp().force_unit.cast<double>();
}

// Any unit vector perpendicular to v.
Eigen::Vector3d across(const Eigen::Vector3d& v) {
  Eigen::Vector3d a = std::fabs(v.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  return v.cross(a).normalized();
}

template <uint32_t StoreBytes>
struct RigOf {
  gh::FakeClock clock;
  gh::RecordingMotors motors;
  gd::RamStorage<StoreBytes> store;
  gd::HostlessRunner runner{motors, clock, store, gh::ImuOutput::kSixAxis, kAccelFs, kGyroFs};
  std::vector<gd::RunEvent> events;
  uint32_t noise_step = 0;

  RigOf() { runner.boot(); }

  void drain() {
    gd::RunEvent e;
    while (runner.pop_event(e)) events.push_back(e);
  }

  // How the IMU sits on the hand (IMU axes -> hand axes); samples are made in hand axes.
  Eigen::Matrix3d imu_to_hand = Eigen::Matrix3d::Identity();
  Eigen::Vector3d g_hand = Eigen::Vector3d(0, 0, -1);  // where the world's gravity is now

  // One sample with gravity (pointing down) at g_down in the hand frame, the hand turning
  // at w_hand. A least-significant-bit dither keeps the IMU health rule's stuck check
  // quiet, as a real part's noise does.
  gd::HostlessFrame sample(const Eigen::Vector3d& g_down,
                           const Eigen::Vector3d& w_hand = Eigen::Vector3d::Zero()) {
    clock.advance_us(kSamplePeriodUs);
    g_hand = g_down;
    const Eigen::Vector3d a_imu = imu_to_hand.transpose() * (-g_down * kG);
    const Eigen::Vector3d w_imu = imu_to_hand.transpose() * w_hand;
    gh::ImuSample s;
    s.time_us = clock.now_us();
    const float lsb = (++noise_step % 2) ? 0.002f : -0.002f;
    for (int i = 0; i < 3; ++i) {
      s.accel_mps2[i] = float(a_imu[i]) + lsb;
      s.gyro_radps[i] = float(w_imu[i]) + lsb;
    }
    const gd::HostlessFrame f = runner.on_sample(s);
    drain();
    return f;
  }

  // One sample of a turn at 90 deg/s towards target, with the gyroscope reading the turn
  // (the world's gravity seen from the hand moves as g' = g x w). False once there.
  bool turn_step(const Eigen::Vector3d& target, gd::HostlessFrame* out = nullptr) {
    const double dt = kSamplePeriodUs * 1e-6, step = 90 * M_PI / 180 * dt;
    const Eigen::Vector3d axis = g_hand.cross(target);
    const double angle = std::atan2(axis.norm(), g_hand.dot(target));
    if (angle < 1e-9) return false;
    const Eigen::Vector3d n = axis.normalized();
    const double d = angle < step ? angle : step;
    const Eigen::Vector3d next = (Eigen::AngleAxisd(d, n) * g_hand).normalized();
    const gd::HostlessFrame f = sample(angle <= step ? target : next, -n * (d / dt));
    if (out) *out = f;
    return true;
  }

  gd::HostlessFrame turn_to(const Eigen::Vector3d& target) {
    gd::HostlessFrame f;
    while (turn_step(target, &f)) {
    }
    return f;
  }

  // Turns to g_down, then holds it, until the event comes (or the limit); returns the time
  // it took.
  uint32_t until(gd::RunEventCode code, const Eigen::Vector3d& g_down, uint32_t limit_us) {
    const uint32_t t0 = clock.now_us();
    const size_t seen = events.size();
    auto came = [&] {
      for (size_t i = seen; i < events.size(); ++i)
        if (events[i].code == code) return true;
      return false;
    };
    while (!came() && clock.now_us() - t0 < limit_us)
      if (!turn_step(g_down)) sample(g_down);
    if (!came()) ADD_FAILURE() << "event " << int(code) << " did not come in " << limit_us << " us";
    return clock.now_us() - t0;
  }

  gd::HostlessReply upload(const gd::PlanHeader& h, const std::vector<gd::PlanTrial>& trials) {
    gd::HostlessReply r = runner.begin_plan(h);
    if (!r.ok()) return r;
    for (size_t i = 0; i < trials.size(); ++i) {
      r = runner.add_trial(uint16_t(i), trials[i]);
      if (!r.ok()) return r;
    }
    return runner.commit_plan(uint16_t(trials.size()));
  }
};

using Rig = RigOf<64 * 1024>;
const Eigen::Vector3d kRest(0, 0, -1);

}  // namespace

TEST(HostlessRunner, TrialsRunFromTheButtonAndEachIsLoggedBeforeTheNext) {
  Rig rig;
  const gd::PlanHeader h = header(2);
  const std::vector<gd::PlanTrial> trials = {trial(1, 4, kSideways), trial(2, 3, kOther)};
  ASSERT_TRUE(rig.upload(h, trials).ok());
  ASSERT_TRUE(rig.runner.start().ok());
  rig.drain();
  ASSERT_EQ(rig.events.back().code, gd::RunEventCode::kRest);

  // The rest (1 s) then the ready pattern (2 x 150 ms + 150 ms): ready after 1.45 s.
  const uint32_t to_ready = rig.until(gd::RunEventCode::kReady, kRest, 5'000 * kMs);
  EXPECT_GE(to_ready, 1'000 * kMs + gd::pattern_length_us(gd::kReadyPattern));
  EXPECT_LE(to_ready, 1'000 * kMs + gd::pattern_length_us(gd::kReadyPattern) + kSamplePeriodUs);
  EXPECT_TRUE(rig.motors.all_off());

  // Trial 1: aligned at once, success after the hold.
  const Eigen::Vector3d f1 = force_direction(h, trials[0]);
  rig.runner.on_button(true, rig.clock.now_us());
  rig.drain();
  ASSERT_EQ(rig.events.back().code, gd::RunEventCode::kTrialStarted);
  const uint32_t t_start = rig.clock.now_us();
  rig.turn_to(f1);
  const uint32_t turned = rig.clock.now_us() - t_start;
  const uint32_t to_success = turned + rig.until(gd::RunEventCode::kSuccess, f1, 3'000 * kMs);
  // The hold starts when the estimate enters the 3 degree threshold: 3 / 90 s = 3.3 samples
  // before the turn's end if the estimate follows the gyroscope exactly.
  EXPECT_GE(to_success, turned + 500 * kMs - 4 * kSamplePeriodUs);
  EXPECT_LE(to_success, turned + 500 * kMs + 5 * kSamplePeriodUs);
  EXPECT_EQ(rig.runner.log().records(), 1);
  uint16_t idx = 0;
  gg::TrialResult result;
  ASSERT_TRUE(rig.runner.pop_result(idx, result));
  EXPECT_EQ(idx, 1);
  EXPECT_TRUE(result.success);

  // Trial 2: held 40 degrees off its force, it times out at 5 s.
  const Eigen::Vector3d f2 = force_direction(h, trials[1]);
  const Eigen::Vector3d off =
      (std::cos(40 * M_PI / 180) * f2 + std::sin(40 * M_PI / 180) * across(f2)).normalized();
  rig.until(gd::RunEventCode::kReady, kRest, 5'000 * kMs);
  rig.runner.on_button(true, rig.clock.now_us());
  rig.turn_to(off);
  bool motors_were_on = false;
  for (int i = 0; i < 100; ++i) {
    const gd::HostlessFrame f = rig.sample(off);
    for (uint8_t d : f.pwm.duty) motors_were_on |= d != 0;
  }
  EXPECT_TRUE(motors_were_on);
  const gd::HostlessFrame mid = rig.sample(off);
  EXPECT_NEAR(double(mid.error_deg), 40.0, 2.0);
  rig.until(gd::RunEventCode::kTimeout, off, 6'000 * kMs);
  rig.until(gd::RunEventCode::kPlanDone, kRest, 2'000 * kMs);
  EXPECT_FALSE(rig.runner.running());
  EXPECT_TRUE(rig.motors.all_off());

  ASSERT_EQ(rig.runner.log().records(), 2);
  gd::LogRecord r1, r2;
  ASSERT_EQ(rig.runner.log().read(0, r1), gd::StoreStatus::kOk);
  ASSERT_EQ(rig.runner.log().read(1, r2), gd::StoreStatus::kOk);
  EXPECT_EQ(r1.trial.trial_index, 1);
  EXPECT_TRUE(r1.success);
  EXPECT_NEAR(r1.completion_s, to_success * 1e-6, 0.011);
  EXPECT_EQ(r1.trial.k, 4);
  EXPECT_EQ(r2.trial.trial_index, 2);
  EXPECT_FALSE(r2.success);
  EXPECT_FLOAT_EQ(r2.completion_s, 5.0f);
  EXPECT_NEAR(r2.final_error_deg, 40.0, 2.0);
  EXPECT_EQ(std::memcmp(r2.trial.wrench, kOther, sizeof kOther), 0);
  EXPECT_GT(r2.samples, 490u);
}

TEST(HostlessRunner, ThePressOnlyCountsOnceReady) {
  Rig rig;
  ASSERT_TRUE(rig.upload(header(1), {trial(1, 4, kSideways)}).ok());
  ASSERT_TRUE(rig.runner.start().ok());
  for (int i = 0; i < 50; ++i) rig.sample(kRest);
  rig.runner.on_button(true, rig.clock.now_us());  // during the rest: ignored
  rig.drain();
  EXPECT_EQ(rig.runner.phase(), gd::RunPhase::kRest);
  rig.until(gd::RunEventCode::kReady, kRest, 5'000 * kMs);
  rig.runner.on_button(false, rig.clock.now_us());  // a release is not a press
  EXPECT_EQ(rig.runner.phase(), gd::RunPhase::kWaitButton);
  rig.runner.on_button(true, rig.clock.now_us());
  EXPECT_EQ(rig.runner.phase(), gd::RunPhase::kTrial);
}

// A one-trial plan whose trial runs, the hand held 45 degrees off its force: motors on.
void start_guiding(Rig& rig) {
  const gd::PlanHeader h = header(1);
  const gd::PlanTrial t = trial(1, 4, kSideways);
  ASSERT_TRUE(rig.upload(h, {t}).ok());
  ASSERT_TRUE(rig.runner.start().ok());
  rig.until(gd::RunEventCode::kReady, kRest, 5'000 * kMs);
  rig.runner.on_button(true, rig.clock.now_us());
  const Eigen::Vector3d f = force_direction(h, t);
  rig.turn_to((f + across(f)).normalized());
  for (int i = 0; i < 20; ++i) rig.sample(rig.g_hand);
  ASSERT_FALSE(rig.motors.all_off());
}

TEST(HostlessRunner, AStaleImuTurnsTheMotorsOffWithinItsTimeoutAndTheTrialStillEnds) {
  Rig rig;
  start_guiding(rig);
  if (HasFatalFailure()) return;
  // The IMU goes silent: the control loop ticks every millisecond.
  const uint32_t last_sample = rig.clock.now_us();
  while (!rig.motors.all_off() && rig.clock.now_us() - last_sample < 1'000 * kMs) {
    rig.clock.advance_us(kMs);
    rig.runner.tick(rig.clock.now_us());
    rig.drain();
  }
  const uint32_t latency_us = rig.clock.now_us() - last_sample;
  std::printf("IMU stale -> motors off: %.1f ms after the last sample (rule: %d ms)\n",
              latency_us / 1000.0, GRASPGUIDE_IMU_STALE_MS);
  EXPECT_EQ(latency_us, uint32_t(GRASPGUIDE_IMU_STALE_MS) * kMs);
  EXPECT_EQ(rig.events.back().code, gd::RunEventCode::kImuFault);
  EXPECT_EQ(rig.runner.imu_faults().stale, 1u);
  // Silent until the timeout: the trial ends on the device's clock, as a failure.
  for (int i = 0; i < 6000 && rig.runner.phase() == gd::RunPhase::kTrial; ++i) {
    rig.clock.advance_us(kMs);
    rig.runner.tick(rig.clock.now_us());
  }
  rig.drain();
  ASSERT_EQ(rig.runner.log().records(), 1);
  gd::LogRecord r;
  ASSERT_EQ(rig.runner.log().read(0, r), gd::StoreStatus::kOk);
  EXPECT_FALSE(r.success);
  EXPECT_FLOAT_EQ(r.completion_s, 5.0f);
  EXPECT_EQ(r.imu_faults, 1);
}

TEST(HostlessRunner, AStuckImuHoldsTheMotorsOff) {
  Rig rig;
  start_guiding(rig);
  if (HasFatalFailure()) return;
  const Eigen::Vector3d off = rig.g_hand;
  gh::ImuSample frozen;
  for (int i = 0; i < 3; ++i) frozen.accel_mps2[i] = float(-off[i]) * kG;
  int on_after_stuck = 0;
  for (int i = 0; i < 40; ++i) {
    rig.clock.advance_us(kSamplePeriodUs);
    frozen.time_us = rig.clock.now_us();
    const gd::HostlessFrame fr = rig.runner.on_sample(frozen);
    if (i >= GRASPGUIDE_IMU_STUCK_SAMPLES) {
      EXPECT_EQ(fr.status, gg::Status::kImuStuck);
      on_after_stuck += !rig.motors.all_off();
    }
  }
  EXPECT_EQ(on_after_stuck, 0);
  EXPECT_EQ(rig.runner.imu_faults().stuck, 1u);
  rig.drain();
  int fault_events = 0;
  for (const gd::RunEvent& e : rig.events) fault_events += e.code == gd::RunEventCode::kImuFault;
  EXPECT_EQ(fault_events, 1);
}

TEST(HostlessRunner, AFaultThatBeganBeforeTheTrialIsInItsRecord) {
  Rig rig;
  ASSERT_TRUE(rig.upload(header(1), {trial(1, 4, kSideways)}).ok());
  ASSERT_TRUE(rig.runner.start().ok());
  rig.until(gd::RunEventCode::kReady, kRest, 5'000 * kMs);
  gh::ImuSample frozen;  // frozen from here on: stuck before the press
  frozen.accel_mps2[2] = kG;
  for (int i = 0; i <= GRASPGUIDE_IMU_STUCK_SAMPLES; ++i) {
    rig.clock.advance_us(kSamplePeriodUs);
    frozen.time_us = rig.clock.now_us();
    rig.runner.on_sample(frozen);
  }
  ASSERT_EQ(rig.runner.imu_status(), gg::Status::kImuStuck);
  rig.runner.on_button(true, rig.clock.now_us());
  for (int i = 0; i < 600 && rig.runner.phase() == gd::RunPhase::kTrial; ++i) {
    rig.clock.advance_us(kSamplePeriodUs);
    frozen.time_us = rig.clock.now_us();
    EXPECT_EQ(rig.runner.on_sample(frozen).status, gg::Status::kImuStuck);
    EXPECT_TRUE(rig.motors.all_off());
  }
  gd::LogRecord r;
  ASSERT_EQ(rig.runner.log().read(0, r), gd::StoreStatus::kOk);
  EXPECT_FALSE(r.success);
  EXPECT_EQ(r.imu_faults, 1);
  EXPECT_FLOAT_EQ(r.first_entry_s, -1.0f);
}

TEST(HostlessRunner, TheMountingRotatesTheImuIntoTheHand) {
  // The IMU turned 90 degrees about the hand's z: its x is the hand's y.
  Rig plain, mounted;
  gd::PlanHeader h = header(1);
  const gd::PlanTrial t = trial(1, 4, kSideways);
  ASSERT_TRUE(plain.upload(h, {t}).ok());
  h.imu_to_hand_wxyz[0] = h.imu_to_hand_wxyz[3] = float(std::sqrt(0.5));
  ASSERT_TRUE(mounted.upload(h, {t}).ok());
  mounted.imu_to_hand = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  for (Rig* r : {&plain, &mounted}) {
    ASSERT_TRUE(r->runner.start().ok());
    r->until(gd::RunEventCode::kReady, kRest, 5'000 * kMs);
    r->runner.on_button(true, r->clock.now_us());
  }
  const Eigen::Vector3d f = force_direction(h, t);
  const Eigen::Vector3d g_hand = (f + 0.5 * across(f)).normalized();
  gd::HostlessFrame a, b;
  plain.turn_to(g_hand);
  mounted.turn_to(g_hand);
  for (int i = 0; i < 30; ++i) {
    a = plain.sample(g_hand);
    b = mounted.sample(g_hand);
  }
  EXPECT_GT(double(a.error_deg), 20.0);
  EXPECT_NEAR(double(a.error_deg), double(b.error_deg), 1e-3);
}

TEST(HostlessRunner, CommitRefusesPlansThatCannotGuideAndKeepsTheStoredOne) {
  Rig rig;
  ASSERT_TRUE(rig.upload(header(1), {trial(1, 4, kSideways)}).ok());
  gd::PlanHeader collinear = header(1);
  for (int i = 0; i < 3; ++i) {  // three contacts on one line
    collinear.hand_k3[i][0] = 0.01f * float(i);
    collinear.hand_k3[i][1] = 0.02f * float(i);
    collinear.hand_k3[i][2] = 0.03f * float(i);
  }
  std::strcpy(collinear.participant, "U2");
  const gd::HostlessReply r = rig.upload(collinear, {trial(7, 3, kSideways)});
  EXPECT_EQ(r.refusal, gd::HostlessRefusal::kCoreStatus);
  EXPECT_NE(r.status, gg::Status::kOk);
  EXPECT_EQ(r.detail, 0);
  ASSERT_TRUE(rig.runner.plan_stored());
  EXPECT_STREQ(rig.runner.plan().header.participant, "U1");

  // Incomplete: two announced, one sent.
  ASSERT_TRUE(rig.runner.begin_plan(header(2)).ok());
  ASSERT_TRUE(rig.runner.add_trial(0, trial(1, 4, kSideways)).ok());
  const gd::HostlessReply short_plan = rig.runner.commit_plan(2);
  EXPECT_EQ(short_plan.refusal, gd::HostlessRefusal::kBadPlan);
  EXPECT_EQ(short_plan.detail, 1);  // the first missing position
  // Out of order.
  ASSERT_TRUE(rig.runner.begin_plan(header(2)).ok());
  EXPECT_EQ(rig.runner.add_trial(1, trial(2, 4, kSideways)).refusal, gd::HostlessRefusal::kBadPlan);
  // Without a begin.
  gd::HostlessRunner fresh(rig.motors, rig.clock, rig.store, gh::ImuOutput::kSixAxis, kAccelFs,
                           kGyroFs);
  EXPECT_EQ(fresh.commit_plan(1).refusal, gd::HostlessRefusal::kNoPlan);
}

TEST(HostlessRunner, ANewPlanIsRefusedWhileTheLogHoldsAnothersRecords) {
  Rig rig;
  const gd::PlanHeader h = header(1);
  const gd::PlanTrial t = trial(1, 4, kSideways);
  ASSERT_TRUE(rig.upload(h, {t}).ok());
  ASSERT_TRUE(rig.runner.start().ok());
  rig.until(gd::RunEventCode::kReady, kRest, 5'000 * kMs);
  rig.runner.on_button(true, rig.clock.now_us());
  rig.until(gd::RunEventCode::kSuccess, force_direction(h, t), 3'000 * kMs);
  rig.until(gd::RunEventCode::kPlanDone, kRest, 2'000 * kMs);
  gd::PlanHeader other = h;
  std::strcpy(other.participant, "U2");
  EXPECT_EQ(rig.upload(other, {t}).refusal, gd::HostlessRefusal::kLogNotEmpty);
  EXPECT_TRUE(rig.upload(h, {t}).ok());  // the same plan again: its records stay valid
  ASSERT_EQ(rig.runner.log().erase(), gd::StoreStatus::kOk);
  EXPECT_TRUE(rig.upload(other, {t}).ok());
}

TEST(HostlessRunner, APowerCutLosesOnlyTheTrialThatWasRunning) {
  Rig rig;
  const gd::PlanHeader h = header(3);
  const std::vector<gd::PlanTrial> trials = {trial(1, 4, kSideways), trial(2, 3, kOther),
                                             trial(3, 4, kOther)};
  ASSERT_TRUE(rig.upload(h, trials).ok());
  ASSERT_TRUE(rig.runner.start().ok());
  rig.until(gd::RunEventCode::kReady, kRest, 5'000 * kMs);
  rig.runner.on_button(true, rig.clock.now_us());
  rig.until(gd::RunEventCode::kSuccess, force_direction(h, trials[0]), 3'000 * kMs);
  rig.until(gd::RunEventCode::kReady, kRest, 5'000 * kMs);
  rig.runner.on_button(true, rig.clock.now_us());
  for (int i = 0; i < 20; ++i) rig.sample(kRest);  // trial 2 under way: the power goes

  // Power back: a new runner on the same store resumes at trial 2.
  gh::RecordingMotors motors;
  gd::HostlessRunner again(motors, rig.clock, rig.store, gh::ImuOutput::kSixAxis, kAccelFs,
                           kGyroFs);
  ASSERT_EQ(again.boot(), gd::StoreStatus::kOk);
  ASSERT_TRUE(again.plan_stored());
  EXPECT_EQ(again.log().records(), 1);
  ASSERT_TRUE(again.start().ok());
  EXPECT_EQ(again.position(), 1);
  gd::RunEvent e;
  ASSERT_TRUE(again.pop_event(e));
  EXPECT_EQ(e.code, gd::RunEventCode::kRest);
  EXPECT_EQ(e.trial_index, 2);
}

TEST(HostlessRunner, AFullLogStopsTheRunAndOverwritesNothing) {
  // Room for the plan and exactly one record.
  RigOf<gd::kPlanRegionBytes + gd::kLogSlotBytes> rig;
  const gd::PlanHeader h = header(2);
  const std::vector<gd::PlanTrial> trials = {trial(1, 4, kSideways), trial(2, 4, kSideways)};
  ASSERT_TRUE(rig.upload(h, trials).ok());
  ASSERT_EQ(rig.runner.log().capacity(), 1);
  ASSERT_TRUE(rig.runner.start().ok());
  rig.until(gd::RunEventCode::kReady, kRest, 5'000 * kMs);
  rig.runner.on_button(true, rig.clock.now_us());
  rig.until(gd::RunEventCode::kSuccess, force_direction(h, trials[0]), 3'000 * kMs);
  // The next trial has no room: the run stops before it, with the event that says why.
  rig.until(gd::RunEventCode::kLogFull, kRest, 3'000 * kMs);
  EXPECT_FALSE(rig.runner.running());
  EXPECT_TRUE(rig.motors.all_off());
  EXPECT_EQ(rig.runner.start().refusal, gd::HostlessRefusal::kLogFull);
  gd::LogRecord r;
  ASSERT_EQ(rig.runner.log().read(0, r), gd::StoreStatus::kOk);
  EXPECT_EQ(r.trial.trial_index, 1);
  EXPECT_TRUE(r.success);
  EXPECT_EQ(rig.runner.log().append(r, gd::plan_id(rig.runner.plan())), gd::StoreStatus::kFull);
  EXPECT_EQ(rig.runner.log().records(), 1);
}

TEST(HostlessRunner, ThePlansCalibrationShapesEveryGuidedFrame) {
  // The same trial under the identity and under a participant's calibration: the error and
  // alpha are the same, the PWM is floor_i + G (gain_i |m_i|) rounded half up (float64,
  // from the levels of an independent solve), motor by motor.
  Rig plain, calibrated;
  gd::PlanHeader h = header(1);
  gd::PlanTrial t = trial(1, 4, kSideways);
  t.mode = 1;  // V: the span is alpha, so the duties move with the error
  ASSERT_TRUE(plain.upload(h, {t}).ok());
  const uint8_t floor[4] = {40, 90, 0, 120};
  const float gain[4] = {1.5f, 0.5f, 4.0f, 0.75f};
  std::memcpy(h.pwm_floor, floor, sizeof floor);
  std::memcpy(h.gain, gain, sizeof gain);
  ASSERT_TRUE(calibrated.upload(h, {t}).ok());
  for (Rig* r : {&plain, &calibrated}) {
    ASSERT_TRUE(r->runner.start().ok());
    r->until(gd::RunEventCode::kReady, kRest, 5'000 * kMs);
    r->runner.on_button(true, r->clock.now_us());
  }
  // The levels, solved apart from the runner.
  gg::Scene<Real> s;
  s.k = 4;
  s.contacts.setZero();
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) s.contacts(j, i) = h.hand_k4[i][j];
  gg::Guidance<Real> g;
  gg::Vec6<Real> w;
  for (int j = 0; j < 6; ++j) w(j) = t.wrench[j];
  ASSERT_EQ(g.set_scene(s), gg::Status::kOk);
  ASSERT_EQ(g.set_wrench(w), gg::Status::kOk);
  gg::FrameResult<Real> probe;
  ASSERT_EQ(g.update(Eigen::Matrix<Real, 4, 1>(1, 0, 0, 0), probe), gg::Status::kOk);
  const Eigen::Vector3d f = g.grasp().force_unit.cast<double>();
  int frames = 0, exact = 0, changed = 0;
  for (double off_deg : {50.0, 30.0, 15.0, 8.0}) {
    const double a = off_deg * M_PI / 180;
    const Eigen::Vector3d target = (std::cos(a) * f + std::sin(a) * across(f)).normalized();
    plain.turn_to(target);
    calibrated.turn_to(target);
    for (int i = 0; i < 20; ++i) {
      const gd::HostlessFrame p = plain.sample(target);
      const gd::HostlessFrame c = calibrated.sample(target);
      ASSERT_TRUE(c.trial_running);
      EXPECT_EQ(double(p.error_deg), double(c.error_deg));
      EXPECT_EQ(double(p.alpha), double(c.alpha));
      for (int m = 0; m < 4; ++m) {
        const double level = std::fabs(double(g.grasp().levels[m]));
        const double span = t.mode == 0 ? double(gg::kPwmSpan) : double(c.alpha);
        double want = 0;
        if (level > gg::kMotorOffLevel) {
          const double x = double(floor[m]) + span * (double(gain[m]) * level);
          want = std::min(255.0, std::max(0.0, std::floor(x + 0.5)));
        }
        const int got = c.pwm.duty[m];
        EXPECT_LE(std::fabs(got - want), 1.0) << "motor " << m << " at " << off_deg << " deg";
        exact += got == int(want);
        changed += c.pwm.duty[m] != p.pwm.duty[m];
        ++frames;
      }
    }
  }
  EXPECT_EQ(exact, frames) << "motor frames equal to the float64 formula";
  EXPECT_GT(changed, frames / 2) << "the calibration changed too few duties to test it";
}

TEST(HostlessRunner, ABadCalibrationIsRefusedAtPlanBeginNamingItsField) {
  Rig rig;
  gd::PlanHeader h = header(1);
  h.pwm_floor[1] = 255;
  gd::HostlessReply r = rig.runner.begin_plan(h);
  EXPECT_EQ(r.refusal, gd::HostlessRefusal::kBadPlan);
  EXPECT_EQ(r.detail, uint8_t(gd::PlanBeginField::kPwmFloor));
  h = header(1);
  h.gain[3] = std::nanf("");
  r = rig.runner.begin_plan(h);
  EXPECT_EQ(r.refusal, gd::HostlessRefusal::kBadPlan);
  EXPECT_EQ(r.detail, uint8_t(gd::PlanBeginField::kGain));
  EXPECT_EQ(13, int(gd::PlanBeginField::kPwmFloor));  // PLAN_BEGIN's schema order
  EXPECT_EQ(14, int(gd::PlanBeginField::kGain));
}

TEST(HostlessRunner, APlanOfAnOlderLayoutIsNotRunAndSaysSo) {
  Rig rig;
  ASSERT_TRUE(rig.upload(header(1), {trial(1, 4, kSideways)}).ok());
  rig.store.bytes()[4] = 1;  // the plan's layout version: an older firmware's
  gd::HostlessRunner rebooted(rig.motors, rig.clock, rig.store, gh::ImuOutput::kSixAxis, kAccelFs,
                              kGyroFs);
  EXPECT_EQ(rebooted.boot(), gd::StoreStatus::kOk);  // the log is fine
  EXPECT_EQ(rebooted.plan_status(), gd::StoreStatus::kOldLayout);
  EXPECT_FALSE(rebooted.plan_stored());
  EXPECT_EQ(rebooted.start().refusal, gd::HostlessRefusal::kNoPlan);
  EXPECT_FALSE(rebooted.running());
}

// Waits for the ready pattern, presses, and holds the hand on the trial's force until it
// succeeds.
void run_to_success(Rig& rig, const gd::PlanHeader& h, const gd::PlanTrial& t) {
  rig.until(gd::RunEventCode::kReady, kRest, 5'000 * kMs);
  rig.runner.on_button(true, rig.clock.now_us());
  rig.until(gd::RunEventCode::kSuccess, force_direction(h, t), 3'000 * kMs);
}

// The trial_index of every valid record, oldest first.
std::vector<uint16_t> logged_trials(Rig& rig) {
  std::vector<uint16_t> out;
  for (uint16_t i = 0; i < rig.runner.log().records(); ++i) {
    gd::LogRecord r;
    EXPECT_EQ(rig.runner.log().read(i, r), gd::StoreStatus::kOk);
    out.push_back(r.trial.trial_index);
  }
  return out;
}

// One bit of the slot's record flipped (flash wear): the slot reads torn.
void damage_slot(Rig& rig, uint16_t slot) {
  rig.store.bytes()[gd::kPlanRegionBytes + uint32_t(slot) * gd::kLogSlotBytes + 12] ^= 0x10;
}

TEST(HostlessRunner, ADamagedRecordsTrialRunsAgainAndNoTrialRunsTwice) {
  Rig rig;
  const gd::PlanHeader h = header(4);
  const std::vector<gd::PlanTrial> trials = {trial(1, 4, kSideways), trial(2, 3, kOther),
                                             trial(3, 4, kOther), trial(4, 3, kSideways)};
  ASSERT_TRUE(rig.upload(h, trials).ok());
  ASSERT_TRUE(rig.runner.start().ok());
  for (int i = 0; i < 3; ++i) run_to_success(rig, h, trials[size_t(i)]);
  rig.runner.stop();
  ASSERT_EQ(logged_trials(rig), (std::vector<uint16_t>{1, 2, 3}));

  // Trial 2's record goes bad; after a restart the run resumes with trial 2, then skips
  // trial 3 (recorded) and ends with trial 4.
  damage_slot(rig, 1);
  ASSERT_EQ(rig.runner.boot(), gd::StoreStatus::kOk);
  ASSERT_EQ(rig.runner.log().torn(), 1);
  ASSERT_EQ(rig.runner.log().records(), 2);
  rig.events.clear();
  ASSERT_TRUE(rig.runner.start().ok());
  rig.drain();
  ASSERT_FALSE(rig.events.empty());
  EXPECT_EQ(rig.events.back().code, gd::RunEventCode::kRest);
  EXPECT_EQ(rig.events.back().trial_index, 2);
  EXPECT_EQ(rig.runner.position(), 1);
  run_to_success(rig, h, trials[1]);
  rig.until(gd::RunEventCode::kRest, kRest, 2'000 * kMs);
  EXPECT_EQ(rig.events.back().trial_index, 4);
  EXPECT_EQ(rig.runner.position(), 3);
  run_to_success(rig, h, trials[3]);
  rig.until(gd::RunEventCode::kPlanDone, kRest, 2'000 * kMs);
  EXPECT_EQ(logged_trials(rig), (std::vector<uint16_t>{1, 3, 2, 4}));

  // Every trial has a record now: another start runs nothing.
  rig.events.clear();
  ASSERT_TRUE(rig.runner.start().ok());
  rig.drain();
  ASSERT_EQ(rig.events.size(), 1u);
  EXPECT_EQ(rig.events.back().code, gd::RunEventCode::kPlanDone);
  EXPECT_FALSE(rig.runner.running());
}

TEST(HostlessRunner, ADamagedRecordOfAFinishedPlanRunsOnlyItsTrialAgain) {
  Rig rig;
  const gd::PlanHeader h = header(4);
  const std::vector<gd::PlanTrial> trials = {trial(1, 4, kSideways), trial(2, 3, kOther),
                                             trial(3, 4, kOther), trial(4, 3, kSideways)};
  ASSERT_TRUE(rig.upload(h, trials).ok());
  ASSERT_TRUE(rig.runner.start().ok());
  for (const gd::PlanTrial& t : trials) run_to_success(rig, h, t);
  rig.until(gd::RunEventCode::kPlanDone, kRest, 2'000 * kMs);
  damage_slot(rig, 1);
  ASSERT_EQ(rig.runner.boot(), gd::StoreStatus::kOk);
  ASSERT_TRUE(rig.runner.start().ok());
  EXPECT_EQ(rig.runner.position(), 1);
  run_to_success(rig, h, trials[1]);
  rig.until(gd::RunEventCode::kPlanDone, kRest, 2'000 * kMs);
  EXPECT_EQ(logged_trials(rig), (std::vector<uint16_t>{1, 3, 4, 2}));
}

TEST(HostlessRunner, AnUploadThatIsNeverCommittedLeavesTheStoredPlanInUse) {
  Rig rig;
  const gd::PlanHeader h = header(1);
  const gd::PlanTrial t = trial(1, 4, kSideways);
  ASSERT_TRUE(rig.upload(h, {t}).ok());
  const uint32_t stored_id = gd::plan_id(rig.runner.plan());

  // Another plan is begun and one of its two trials sent, then the host goes away.
  gd::PlanHeader other = header(2);
  std::strcpy(other.participant, "U9");
  ASSERT_TRUE(rig.runner.begin_plan(other).ok());
  ASSERT_TRUE(rig.runner.add_trial(0, trial(7, 3, kOther)).ok());
  // LOG_INFO's view: the stored plan, as it is on the store.
  EXPECT_TRUE(rig.runner.plan_stored());
  EXPECT_STREQ(rig.runner.plan().header.participant, "U1");
  EXPECT_EQ(rig.runner.plan().header.trial_count, 1);

  // HOSTLESS_RUN runs the stored plan; the open upload is dropped.
  ASSERT_TRUE(rig.runner.start().ok());
  rig.drain();
  EXPECT_EQ(rig.events.back().code, gd::RunEventCode::kRest);
  EXPECT_EQ(rig.events.back().trial_index, 1);
  EXPECT_EQ(gd::plan_id(rig.runner.plan()), stored_id);
  run_to_success(rig, h, t);
  rig.until(gd::RunEventCode::kPlanDone, kRest, 2'000 * kMs);
  gd::LogRecord r;
  uint32_t id = 0;
  ASSERT_EQ(rig.runner.log().read(0, r, &id), gd::StoreStatus::kOk);
  EXPECT_EQ(id, stored_id);
  EXPECT_EQ(r.trial.trial_index, 1);
  EXPECT_EQ(rig.runner.add_trial(1, trial(8, 3, kOther)).refusal, gd::HostlessRefusal::kNoPlan);
  EXPECT_EQ(rig.runner.commit_plan(2).refusal, gd::HostlessRefusal::kNoPlan);
}

TEST(HostlessRunner, AnUploadCommitsAfterTheStoredPlanWasAskedFor) {
  Rig rig;
  ASSERT_TRUE(rig.upload(header(1), {trial(1, 4, kSideways)}).ok());
  ASSERT_EQ(rig.runner.log().erase(), gd::StoreStatus::kOk);
  gd::PlanHeader other = header(2);
  std::strcpy(other.participant, "U2");
  ASSERT_TRUE(rig.runner.begin_plan(other).ok());
  ASSERT_TRUE(rig.runner.add_trial(0, trial(5, 3, kOther)).ok());
  EXPECT_STREQ(rig.runner.plan().header.participant, "U1");  // LOG_INFO in between
  ASSERT_TRUE(rig.runner.add_trial(1, trial(6, 4, kSideways)).ok());
  ASSERT_TRUE(rig.runner.commit_plan(2).ok());
  EXPECT_STREQ(rig.runner.plan().header.participant, "U2");
  EXPECT_EQ(rig.runner.plan().header.trial_count, 2);
  EXPECT_EQ(rig.runner.plan().trials[1].trial_index, 6);
  // What a restart loads is what ran.
  gd::HostlessRunner rebooted(rig.motors, rig.clock, rig.store, gh::ImuOutput::kSixAxis, kAccelFs,
                              kGyroFs);
  rebooted.boot();
  EXPECT_EQ(gd::plan_id(rebooted.plan()), gd::plan_id(rig.runner.plan()));
}

TEST(HostlessRunner, ASampleOlderThanTheLastAbortsTheTrialWithNoRecord) {
  Rig rig;
  start_guiding(rig);
  if (HasFatalFailure()) return;
  rig.drain();
  const size_t seen = rig.events.size();
  gh::ImuSample back;
  back.time_us = rig.clock.now_us() - 1;  // 1 us before the last sample
  back.accel_mps2[2] = kG;
  const gd::HostlessFrame f = rig.runner.on_sample(back);
  rig.drain();
  EXPECT_EQ(f.status, gg::Status::kTimeWentBackwards);
  EXPECT_FALSE(f.trial_running);
  EXPECT_TRUE(rig.motors.all_off());
  EXPECT_EQ(rig.runner.log().records(), 0);
  uint16_t idx = 0;
  gg::TrialResult result;
  EXPECT_FALSE(rig.runner.pop_result(idx, result));
  // The trial starts over from its rest: no success or timeout was told.
  ASSERT_GT(rig.events.size(), seen);
  for (size_t i = seen; i < rig.events.size(); ++i) {
    EXPECT_NE(rig.events[i].code, gd::RunEventCode::kTimeout);
    EXPECT_NE(rig.events[i].code, gd::RunEventCode::kSuccess);
  }
  EXPECT_EQ(rig.events.back().code, gd::RunEventCode::kRest);
  EXPECT_EQ(rig.events.back().trial_index, 1);
  EXPECT_EQ(rig.runner.phase(), gd::RunPhase::kRest);

  // Time goes on from the earlier stamp: the trial runs again and its record is honest.
  const gd::PlanHeader h = header(1);
  const gd::PlanTrial t = trial(1, 4, kSideways);
  rig.until(gd::RunEventCode::kReady, kRest, 5'000 * kMs);
  rig.runner.on_button(true, rig.clock.now_us());
  const uint32_t pressed = rig.clock.now_us();
  rig.until(gd::RunEventCode::kSuccess, force_direction(h, t), 3'000 * kMs);
  ASSERT_EQ(rig.runner.log().records(), 1);
  gd::LogRecord r;
  ASSERT_EQ(rig.runner.log().read(0, r), gd::StoreStatus::kOk);
  EXPECT_TRUE(r.success);
  EXPECT_NEAR(r.completion_s, (rig.clock.now_us() - pressed) * 1e-6, 0.011);
  EXPECT_LT(r.completion_s, 3.0f);
}

TEST(HostlessRunner, ATickBeforeTheLastSampleNeverAdvancesTheTrial) {
  Rig rig;
  start_guiding(rig);
  if (HasFatalFailure()) return;
  // A loop's "now" read just before the sample it then handles: the step back is no time.
  rig.runner.tick(rig.clock.now_us() - 5);
  EXPECT_EQ(rig.runner.phase(), gd::RunPhase::kTrial);
  for (int i = 0; i < 20; ++i) rig.sample(rig.g_hand);
  EXPECT_EQ(rig.runner.log().records(), 0);
  EXPECT_EQ(rig.runner.phase(), gd::RunPhase::kTrial);
}
