// The device's safety promises under hostile input (docs/protocol.md "Safety"): every ERROR
// and every dropped frame turns the motors off, a bad trial field is named, a trial always
// ends whatever its timestamps do, and a STOP after half a frame still gets through.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <string>
#include <vector>

#include "common/hand_scenes.h"
#include "graspguide_device/link_device.h"
#include "graspguide_hal/fake_hal.h"

namespace gg = graspguide;
namespace gd = graspguide::device;
namespace gl = graspguide::link;
namespace gh = graspguide::hal;

namespace {

constexpr uint32_t kMs = 1000;

struct Rig {
  gh::FakeClock clock;
  gh::RecordingMotors motors;
  gd::Application app{motors, clock};
  gh::MemoryStream stream;
  gd::LinkDevice device{stream, app, gd::DeviceInfo{}};
  gl::FrameParser host{gl::Accept::kDeviceToHost};
  uint16_t seq = 100;

  std::vector<uint8_t> frame_of(const gl::FrameHeader& h, const uint8_t* payload, size_t size) {
    uint8_t out[gl::kMaxWireFrameSize];
    size_t n = 0;
    EXPECT_EQ(gl::encode_frame(h, payload, size, out, sizeof out, &n), gl::LinkStatus::kOk);
    return std::vector<uint8_t>(out, out + n);
  }
  template <class Msg>
  std::vector<uint8_t> frame_of(const Msg& m) {
    uint8_t out[gl::kMaxWireFrameSize];
    size_t n = 0;
    EXPECT_EQ(gl::write_frame(m, ++seq, out, sizeof out, &n), gl::LinkStatus::kOk);
    return std::vector<uint8_t>(out, out + n);
  }
  void raw(const std::vector<uint8_t>& bytes) {
    stream.host_send(bytes.data(), bytes.size());
    device.poll();
  }
  template <class Msg>
  void send(const Msg& m) {
    raw(frame_of(m));
  }

  // Every frame the device sent since the last call: (id, payload).
  std::vector<std::pair<uint8_t, std::vector<uint8_t>>> received() {
    std::vector<std::pair<uint8_t, std::vector<uint8_t>>> out;
    uint8_t buf[4096];
    const size_t n = stream.host_receive(buf, sizeof buf);
    for (size_t i = 0; i < n; ++i)
      if (host.push(buf[i]) == gl::ParseEvent::kFrame) {
        const auto& f = host.frame();
        out.emplace_back(f.header.msg_id,
                         std::vector<uint8_t>(f.payload, f.payload + f.payload_size));
      }
    return out;
  }
  template <class Msg>
  std::vector<Msg> all(uint8_t id = uint8_t(Msg::kId)) {
    std::vector<Msg> out;
    for (const auto& f : received())
      if (f.first == id) {
        Msg m;
        EXPECT_EQ(gl::unpack(f.second.data(), f.second.size(), &m), gl::LinkStatus::kOk);
        out.push_back(m);
      }
    return out;
  }
};

gl::SetScene scene_msg() {
  gl::SetScene m;
  m.k = 4;
  const auto c = graspguide_test::nominal_hand();
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) m.contacts[i][j] = float(c(j, i));
  return m;
}

gl::StartTrial trial_msg() {
  gl::StartTrial m;
  m.trial_id = 7;
  const float w[6] = {0.4f, -1.0f, 0.3f, 0, 0, 0};
  std::copy(w, w + 6, m.wrench);
  return m;
}

gl::Pose pose_at(uint32_t t_us) {
  gl::Pose p;
  p.host_time_us = t_us;
  return p;
}

// The two ways the motors are on: a running trial, or SET_MOTORS on the bench.
void motors_on_in_trial(Rig& r) {
  r.send(scene_msg());
  r.send(trial_msg());
  r.send(pose_at(0));
  r.received();
  ASSERT_FALSE(r.motors.all_off());
}

void motors_on_by_set_motors(Rig& r) {  // in idle: no scene yet
  gl::SetMotors m;
  m.pwm[0] = m.pwm[2] = 200;
  r.send(m);
  r.received();
  ASSERT_FALSE(r.motors.all_off());
}

struct Offence {
  const char* name;
  // The bytes to send, made on the rig (some need its state); the ERROR code expected back,
  // or kOk for a frame the device drops without an answer (its header is not trusted).
  std::function<std::vector<uint8_t>(Rig&)> bytes;
  gl::ErrorCode answer;
};

std::vector<Offence> offences() {
  std::vector<Offence> o;
  o.push_back({"bad_enum",
               [](Rig& r) {
                 uint8_t payload[gl::kMaxPayloadSize];
                 size_t size = 0;
                 EXPECT_EQ(gl::pack(scene_msg(), payload, sizeof payload, &size),
                           gl::LinkStatus::kOk);
                 payload[62] = 9;  // policy: no such value
                 gl::SetScene probe;
                 EXPECT_EQ(gl::unpack(payload, size, &probe), gl::LinkStatus::kBadEnumValue);
                 gl::FrameHeader h;
                 h.msg_id = uint8_t(gl::MsgId::kSetScene);
                 return r.frame_of(h, payload, size);
               },
               gl::ErrorCode::kBadEnumValue});
  o.push_back({"bad_length",
               [](Rig& r) {
                 const uint8_t three[3] = {1, 2, 3};
                 gl::FrameHeader h;
                 h.msg_id = uint8_t(gl::MsgId::kGetStatus);
                 return r.frame_of(h, three, sizeof three);
               },
               gl::ErrorCode::kBadLength});
  o.push_back({"unknown_id",
               [](Rig& r) {
                 gl::FrameHeader h;
                 h.msg_id = 0x7E;
                 return r.frame_of(h, nullptr, 0);
               },
               gl::ErrorCode::kUnknownId});
  o.push_back({"device_to_host_id",
               [](Rig& r) {
                 gl::FrameHeader h;
                 h.msg_id = uint8_t(gl::MsgId::kAck);
                 const uint8_t two[2] = {0, 0};
                 return r.frame_of(h, two, sizeof two);
               },
               gl::ErrorCode::kUnknownId});
  o.push_back({"bad_version",
               [](Rig& r) {
                 gl::FrameHeader h;
                 h.version = gl::kProtocolVersion + 1;
                 h.msg_id = uint8_t(gl::MsgId::kGetStatus);
                 return r.frame_of(h, nullptr, 0);
               },
               gl::ErrorCode::kBadVersion});
  // START_TRIAL during a trial (not_allowed_in_state) or in idle (no_scene).
  o.push_back(
      {"state_refusal", [](Rig& r) { return r.frame_of(trial_msg()); }, gl::ErrorCode::kOk});
  o.push_back({"bad_crc",
               [](Rig& r) {
                 auto f = r.frame_of(gl::GetStatus{});
                 f[2] ^= 0x01;
                 if (f[2] == 0) f[2] = 0x5A;
                 return f;
               },
               gl::ErrorCode::kOk});
  o.push_back({"too_long",
               [](Rig&) { return std::vector<uint8_t>(gl::kMaxWireFrameSize + 8, 0x11); },
               gl::ErrorCode::kOk});
  o.push_back({"too_short", [](Rig&) { return std::vector<uint8_t>{0x02, 0x01, 0x00}; },
               gl::ErrorCode::kOk});
  return o;
}

void expect_motors_off_after(const Offence& o, void (*setup)(Rig&), const char* context) {
  SCOPED_TRACE(std::string(o.name) + " " + context);
  Rig r;
  setup(r);
  if (::testing::Test::HasFatalFailure()) return;
  auto bytes = o.bytes(r);
  if (bytes.back() != 0) bytes.push_back(0);
  r.raw(bytes);
  const auto errors = r.all<gl::Error>();
  if (o.answer != gl::ErrorCode::kOk) {
    ASSERT_EQ(errors.size(), 1u);
    EXPECT_EQ(errors[0].code, o.answer);
  } else if (std::strcmp(o.name, "state_refusal") == 0) {
    ASSERT_EQ(errors.size(), 1u);
    EXPECT_EQ(errors[0].code, r.app.state() == gd::DeviceState::kIdle
                                  ? gl::ErrorCode::kNoScene
                                  : gl::ErrorCode::kNotAllowedInState);
  } else {
    EXPECT_TRUE(errors.empty());
  }
  EXPECT_TRUE(r.motors.all_off());
}

}  // namespace

TEST(LinkSafety, EveryErrorAndEveryDroppedFrameTurnsTheMotorsOff) {
  for (const Offence& o : offences()) {
    expect_motors_off_after(o, motors_on_in_trial, "during a trial");
    expect_motors_off_after(o, motors_on_by_set_motors, "after SET_MOTORS");
  }
}

TEST(LinkSafety, ACoreErrorAfterSetMotorsTurnsThemOff) {
  Rig r;
  motors_on_by_set_motors(r);
  gl::SetScene bad = scene_msg();
  bad.contacts[1][0] = bad.contacts[0][0];
  bad.contacts[1][1] = bad.contacts[0][1];
  bad.contacts[1][2] = bad.contacts[0][2];
  r.send(bad);
  const auto errors = r.all<gl::Error>();
  ASSERT_EQ(errors.size(), 1u);
  EXPECT_EQ(errors[0].code, gl::ErrorCode::kCoincidentContacts);
  EXPECT_TRUE(r.motors.all_off());
}

TEST(LinkSafety, AnOutOfRangeTrialFieldIsRefusedAndNamed) {
  struct Case {
    float threshold_deg, hold_s, timeout_s;
    const char* field;
  } cases[] = {
      {3, 0.5f, 9.3e12f, "timeout_s"},  // once accepted: overflowed the int64 microseconds
      {3, 1e13f, 90, "hold_s"},         {3, 91, 90, "hold_s"},
      {200, 0.5f, 90, "threshold_deg"}, {3, 0.5f, 0, "timeout_s"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.field);
    Rig r;
    r.send(scene_msg());
    r.received();
    gl::SetScene m = scene_msg();
    m.threshold_deg = c.threshold_deg;
    m.hold_s = c.hold_s;
    m.timeout_s = c.timeout_s;
    r.send(m);
    const auto errors = r.all<gl::Error>();
    ASSERT_EQ(errors.size(), 1u);
    EXPECT_EQ(errors[0].code, gl::ErrorCode::kBadConfig);
    // detail is the field's index in SET_SCENE, as for bad_enum.
    uint8_t i = 0;
    std::string named;
    gl::for_each_field(m, [&](const char* name, const auto&) {
      if (i++ == errors[0].detail) named = name;
    });
    EXPECT_EQ(named, c.field);
    // The previous scene stays: a trial with it starts.
    r.send(trial_msg());
    EXPECT_EQ(r.all<gl::Ack>().size(), 1u);
  }
}

// A host timestamp that jumps 2^31 us or more forward reads as a step back; once, every
// later POSE was refused as time_went_backwards and the 90 s timeout never came.
TEST(LinkSafety, ATimestampJumpOrStepBackEndsTheTrial) {
  for (const uint32_t second : {0x80000000u, 0xFFFFFFFFu, 0x80001000u}) {
    SCOPED_TRACE(second);
    Rig r;
    motors_on_in_trial(r);  // first POSE at 0
    r.send(pose_at(4096));
    r.received();
    r.send(pose_at(4096 + second));
    // Answered by an ERROR, not a TELEMETRY (which a host reads as "the trial goes on").
    const auto answers = r.received();
    ASSERT_EQ(answers.size(), 1u);
    ASSERT_EQ(answers[0].first, uint8_t(gl::MsgId::kError));
    gl::Error e;
    ASSERT_EQ(gl::unpack(answers[0].second.data(), answers[0].second.size(), &e),
              gl::LinkStatus::kOk);
    EXPECT_EQ(e.code, gl::ErrorCode::kTimeWentBackwards);
    EXPECT_EQ(e.detail, uint8_t(gl::DeviceState::kStopped));
    EXPECT_TRUE(r.motors.all_off());
    r.send(gl::GetStatus{});
    const auto st = r.all<gl::Status>();
    ASSERT_EQ(st.size(), 1u);
    EXPECT_EQ(st[0].state, gl::DeviceState::kStopped);
    // The next trial runs normally.
    r.send(trial_msg());
    r.send(pose_at(0));
    EXPECT_FALSE(r.motors.all_off());
  }
}

TEST(LinkSafety, A32BitWrapIsAStepForward) {
  Rig r;
  r.send(scene_msg());
  r.send(trial_msg());
  r.send(pose_at(0xFFFFF000u));
  r.send(pose_at(0x00001000u));  // 8 ms later, across the wrap
  const auto tel = r.all<gl::Telemetry>();
  ASSERT_EQ(tel.size(), 2u);
  EXPECT_EQ(tel[1].solver_status, gl::ErrorCode::kOk);
  EXPECT_FALSE(r.motors.all_off());
}

// Poses whose timestamps stop advancing would keep a trial running forever; the device's
// own clock ends it at the timeout (plus the slack) with a TRIAL_RESULT.
TEST(LinkSafety, FrozenTimestampsCannotKeepATrialRunning) {
  Rig r;
  motors_on_in_trial(r);
  bool ended = false;
  for (int i = 0; i < 1000 && !ended; ++i) {
    r.clock.advance_us(100 * kMs);
    r.send(pose_at(5));
    for (const auto& res : r.all<gl::TrialResult>()) {
      ended = true;
      EXPECT_EQ(res.trial_id, 7);
      EXPECT_FALSE(res.success);
      EXPECT_FLOAT_EQ(res.completion_s, 90.0f);
    }
  }
  ASSERT_TRUE(ended);
  const double ran_s = r.clock.now_us() * 1e-6;
  EXPECT_GE(ran_s, 90.0 + gd::kTrialClockSlackUs * 1e-6);
  EXPECT_LE(ran_s, 90.0 + gd::kTrialClockSlackUs * 1e-6 + 0.1);
  EXPECT_TRUE(r.motors.all_off());
  EXPECT_EQ(r.app.state(), gd::DeviceState::kSceneSet);
  EXPECT_EQ(r.app.counters().trials_ended_by_device_clock, 1u);
}

// A host that stops sending altogether: the watchdog turns the motors off, and poll() alone
// ends the trial on the device clock.
TEST(LinkSafety, ASilentHostsTrialEndsOnTheDeviceClock) {
  Rig r;
  motors_on_in_trial(r);
  r.clock.advance_us(gd::kDefaultStaleTimeoutUs);
  r.device.poll();
  EXPECT_TRUE(r.motors.all_off());
  r.clock.advance_us(90 * 1000 * kMs + gd::kTrialClockSlackUs);
  r.device.poll();
  const auto res = r.all<gl::TrialResult>();
  ASSERT_EQ(res.size(), 1u);
  EXPECT_FALSE(res[0].success);
}

// Half a frame, a pause, then STOP: once, the STOP's bytes merged with the leftover and it
// was lost. The device drops a partial frame after a silence, and the host's delimiter
// before each frame protects it without one.
TEST(LinkSafety, AStopAfterHalfAFrameGetsThrough) {
  for (const bool leading_delimiter : {false, true}) {
    SCOPED_TRACE(leading_delimiter);
    Rig r;
    motors_on_in_trial(r);
    const auto half_pose = r.frame_of(pose_at(4096));
    r.raw(std::vector<uint8_t>(half_pose.begin(), half_pose.begin() + half_pose.size() / 2));
    auto stop = r.frame_of(gl::Stop{});
    if (leading_delimiter) {
      stop.insert(stop.begin(), 0);  // at once, no pause
    } else {
      r.clock.advance_us(gh::kPartialFrameTimeoutUs);
      r.device.poll();
    }
    r.raw(stop);
    EXPECT_EQ(r.all<gl::Ack>().size(), 1u);
    EXPECT_TRUE(r.motors.all_off());
    EXPECT_EQ(r.app.state(), gd::DeviceState::kStopped);
  }
}

// Without either, the merged bytes are one bad frame: this is why both exist.
TEST(LinkSafety, WithoutAPauseOrDelimiterTheMergedFrameIsDropped) {
  Rig r;
  motors_on_in_trial(r);
  const auto half_pose = r.frame_of(pose_at(4096));
  r.raw(std::vector<uint8_t>(half_pose.begin(), half_pose.begin() + half_pose.size() / 2));
  r.clock.advance_us(gh::kPartialFrameTimeoutUs - 1);
  r.device.poll();
  r.raw(r.frame_of(gl::Stop{}));
  EXPECT_TRUE(r.all<gl::Ack>().empty());
  EXPECT_TRUE(r.motors.all_off());  // the dropped frame still turned them off
}

// F1. A core failure inside a running trial does not end the trial, so its TELEMETRY must
// still say the trial runs: runner.py ends its trial loop on a clear flag and then waits for
// a TRIAL_RESULT that never comes, while the device goes on with the trial.
TEST(LinkSafety, ACoreFailureInATrialKeepsTheTrialRunningFlag) {
  for (const bool nan_quaternion : {true, false}) {
    SCOPED_TRACE(nan_quaternion ? "NaN quaternion" : "two contacts on top of each other");
    Rig r;
    motors_on_in_trial(r);
    gl::Pose p = pose_at(10 * kMs);
    if (nan_quaternion) {
      p.quat_wxyz[0] = NAN;
    } else {
      const gl::SetScene s = scene_msg();
      p.has_contacts = true;
      std::memcpy(p.contacts, s.contacts, sizeof p.contacts);
      std::memcpy(p.contacts[1], p.contacts[0], sizeof p.contacts[1]);
    }
    r.send(p);
    const auto tel = r.all<gl::Telemetry>();
    ASSERT_EQ(tel.size(), 1u);
    EXPECT_NE(tel[0].solver_status, gl::ErrorCode::kOk);
    EXPECT_TRUE(r.motors.all_off());
    ASSERT_EQ(r.app.state(), gd::DeviceState::kTrialRunning);
    EXPECT_TRUE(tel[0].flags & gl::kTelemetryFlagTrialRunning);
  }
}

// F2. A timestamp jump ends the trial (like STOP); the host must hear that the trial is
// over from TRIAL_RESULT or ERROR, not from a TELEMETRY that runner.py reads as "wait for
// the TRIAL_RESULT".
TEST(LinkSafety, ATrialEndedByATimestampJumpIsAnsweredWithAnError) {
  Rig r;
  motors_on_in_trial(r);
  r.send(pose_at(0x80000000u));  // 2^31 us after the first POSE
  ASSERT_NE(r.app.state(), gd::DeviceState::kTrialRunning);
  size_t errors = 0, results = 0;
  for (const auto& f : r.received()) {
    errors += f.first == uint8_t(gl::MsgId::kError);
    results += f.first == uint8_t(gl::MsgId::kTrialResult);
  }
  EXPECT_EQ(errors + results, 1u);
}

// F3. The device clock's trial bound reads the time since the first POSE as a signed 32-bit
// difference; one poll gap that takes it past 2^31 us (2147.5 s) hides the end for 35 more
// minutes. With timeout_s = 1800 a gap of 347 s is enough (a sim stopped with Ctrl-Z).
TEST(LinkSafety, AnEighteenHundredSecondTrialEndsAfterASixMinutePollGap) {
  Rig r;
  gl::SetScene s = scene_msg();
  s.timeout_s = 1800;
  r.send(s);
  r.send(trial_msg());
  r.send(pose_at(0));
  r.clock.advance_us(1800500u * kMs);  // 0.5 s before the device's bound
  r.device.poll();
  ASSERT_EQ(r.app.state(), gd::DeviceState::kTrialRunning);
  r.clock.advance_us(347000u * kMs);
  r.device.poll();
  EXPECT_NE(r.app.state(), gd::DeviceState::kTrialRunning);
  EXPECT_EQ(r.all<gl::TrialResult>().size(), 1u);
}

// F4. The trial's device clock starts only at the first POSE whose contacts pass the check;
// after one POSE with non-finite contacts and a host that goes quiet, the trial never ends.
TEST(LinkSafety, ATrialWhoseFirstPoseFailedStillEndsOnTheDeviceClock) {
  Rig r;
  r.send(scene_msg());
  r.send(trial_msg());
  gl::Pose p = pose_at(0);
  p.has_contacts = true;
  p.contacts[0][0] = NAN;
  r.send(p);
  r.clock.advance_us(90 * 1000 * kMs + gd::kTrialClockSlackUs + kMs);
  r.device.poll();
  EXPECT_NE(r.app.state(), gd::DeviceState::kTrialRunning);
}
