// The device end of the link, driven with real frames through an in-memory stream: every
// request gets its answer, garbage is counted and survived, telemetry carries the core's PWM.
#include <gtest/gtest.h>

#include <memory>
#include <vector>

#include "common/hand_scenes.h"
#include "graspguide_device/link_device.h"
#include "graspguide_hal/fake_hal.h"

namespace gg = graspguide;
namespace gd = graspguide::device;
namespace gl = graspguide::link;
namespace gh = graspguide::hal;

struct Received {
  gl::FrameHeader header;
  std::vector<uint8_t> payload;
};

struct LinkRig {
  gh::FakeClock clock;
  gh::RecordingMotors motors;
  gd::Application app{motors, clock};
  gh::MemoryStream stream;
  gd::DeviceInfo info;
  std::unique_ptr<gd::LinkDevice> device;
  gl::FrameParser host_parser{gl::Accept::kDeviceToHost};
  gl::SequenceCounter seq;

  LinkRig() {
    info.board = "test-rig";
    device = std::make_unique<gd::LinkDevice>(stream, app, info);
  }

  template <class Msg>
  uint16_t send(const Msg& m) {
    uint8_t out[gl::kMaxWireFrameSize];
    size_t n = 0;
    const uint16_t s = seq.next();
    EXPECT_EQ(gl::write_frame(m, s, out, sizeof out, &n), gl::LinkStatus::kOk);
    stream.host_send(out, n);
    device->poll();
    return s;
  }

  void send_raw(const std::vector<uint8_t>& bytes) {
    stream.host_send(bytes.data(), bytes.size());
    device->poll();
  }

  std::vector<Received> receive() {
    std::vector<Received> frames;
    uint8_t buf[4096];
    const size_t n = stream.host_receive(buf, sizeof buf);
    for (size_t i = 0; i < n; ++i) {
      if (host_parser.push(buf[i]) == gl::ParseEvent::kFrame) {
        const auto& f = host_parser.frame();
        frames.push_back({f.header, std::vector<uint8_t>(f.payload, f.payload + f.payload_size)});
      }
    }
    return frames;
  }

  template <class Msg>
  Msg only(const std::vector<Received>& frames) {
    EXPECT_EQ(frames.size(), 1u);
    Msg m;
    if (frames.empty()) return m;
    EXPECT_EQ(frames[0].header.msg_id, uint8_t(Msg::kId));
    EXPECT_EQ(gl::unpack(frames[0].payload.data(), frames[0].payload.size(), &m),
              gl::LinkStatus::kOk);
    return m;
  }
};

gl::SetScene scene_msg(int k = 4) {
  gl::SetScene m;
  m.k = uint8_t(k);
  const auto c = graspguide_test::nominal_hand();
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) m.contacts[i][j] = float(c(j, i));
  return m;
}

gl::StartTrial trial_msg(uint16_t id = 1) {
  gl::StartTrial m;
  m.trial_id = id;
  const float w[6] = {0.4f, -1.0f, 0.3f, 0, 0, 0};
  std::copy(w, w + 6, m.wrench);
  return m;
}

TEST(LinkDevice, HelloIsAnsweredWithTheFirmwareIdentity) {
  LinkRig r;
  const uint16_t s = r.send(gl::Hello{});
  const auto reply = r.only<gl::HelloReply>(r.receive());
  EXPECT_EQ(reply.request_seq, s);
  EXPECT_EQ(reply.protocol_version, gl::kProtocolVersion);
  EXPECT_STREQ(reply.board, "test-rig");
  EXPECT_EQ(reply.scalar, sizeof(gg::Real));
  EXPECT_EQ(reply.max_contacts, 4);
}

TEST(LinkDevice, ASceneATrialAndPosesGiveTheCoresPwm) {
  LinkRig r;
  const uint16_t s1 = r.send(scene_msg());
  EXPECT_EQ(r.only<gl::Ack>(r.receive()).request_seq, s1);
  const uint16_t s2 = r.send(trial_msg(5));
  EXPECT_EQ(r.only<gl::Ack>(r.receive()).request_seq, s2);
  gg::Scene<gg::Real> scene;
  scene.k = 4;
  scene.contacts = graspguide_test::nominal_hand().cast<gg::Real>();
  gg::Vec6<double> w;
  w << 0.4, -1.0, 0.3, 0, 0, 0;
  std::mt19937_64 rng(8);
  for (int n = 0; n < 20; ++n) {
    const auto rs = graspguide_test::random_scene(rng, 4);
    gl::Pose p;
    p.host_time_us = uint32_t(n * 4000);
    for (int j = 0; j < 4; ++j) p.quat_wxyz[j] = float(rs.orientation(j));
    r.send(p);
    const auto t = r.only<gl::Telemetry>(r.receive());
    const auto expect = graspguide_test::solve_once<gg::Real>(scene, w, rs.orientation);
    for (int i = 0; i < 4; ++i) EXPECT_EQ(t.pwm[i], expect.frame.pwm.duty[i]) << n;
    EXPECT_EQ(t.host_time_us, p.host_time_us);
    EXPECT_EQ(t.solver_status, gl::ErrorCode::kOk);
    EXPECT_TRUE(t.flags & gl::kTelemetryFlagTrialRunning);
    EXPECT_EQ(graspguide_test::max_pwm_diff(r.motors.last(), expect.frame.pwm), 0);
  }
}

TEST(LinkDevice, RefusalsAndCoreErrorsComeBackAsErrors) {
  LinkRig r;
  gl::Pose p;
  const uint16_t s = r.send(p);
  auto e = r.only<gl::Error>(r.receive());
  EXPECT_EQ(e.request_seq, s);
  EXPECT_EQ(e.code, gl::ErrorCode::kNoScene);
  auto bad = scene_msg();
  bad.contacts[1][0] = bad.contacts[0][0];
  bad.contacts[1][1] = bad.contacts[0][1];
  bad.contacts[1][2] = bad.contacts[0][2];
  r.send(bad);
  EXPECT_EQ(r.only<gl::Error>(r.receive()).code, gl::ErrorCode::kCoincidentContacts);
  r.send(scene_msg());
  r.receive();
  r.send(trial_msg());
  r.receive();
  gl::SetMotors m;
  m.pwm[0] = 200;
  r.send(m);
  e = r.only<gl::Error>(r.receive());
  EXPECT_EQ(e.code, gl::ErrorCode::kNotAllowedInState);
  EXPECT_EQ(e.detail, uint8_t(gl::DeviceState::kTrialRunning));
  // A NaN pose: telemetry says why, motors off.
  p.quat_wxyz[1] = std::numeric_limits<float>::quiet_NaN();
  r.send(p);
  const auto t = r.only<gl::Telemetry>(r.receive());
  EXPECT_EQ(t.solver_status, gl::ErrorCode::kNonFiniteInput);
  EXPECT_TRUE(r.motors.all_off());
}

TEST(LinkDevice, StopAnswersAndSwitchesOffAtOnce) {
  LinkRig r;
  r.send(scene_msg());
  r.send(trial_msg());
  gl::Pose p;
  r.send(p);
  r.receive();
  ASSERT_FALSE(r.motors.all_off());
  const uint16_t s = r.send(gl::Stop{});
  EXPECT_EQ(r.only<gl::Ack>(r.receive()).request_seq, s);
  EXPECT_TRUE(r.motors.all_off());
  r.send(gl::GetStatus{});
  EXPECT_EQ(r.only<gl::Status>(r.receive()).state, gl::DeviceState::kStopped);
}

TEST(LinkDevice, GarbageIsCountedAndTheLinkRecovers) {
  LinkRig r;
  std::mt19937_64 rng(1);
  std::vector<uint8_t> junk(500);
  for (auto& b : junk) b = uint8_t(rng());
  junk.push_back(0);
  r.send_raw(junk);
  r.receive();  // a junk frame whose CRC happens to pass could be answered; none expected
  // A frame with one flipped bit: counted as bad, never answered.
  uint8_t out[gl::kMaxWireFrameSize];
  size_t n = 0;
  ASSERT_EQ(gl::write_frame(gl::GetStatus{}, 77, out, sizeof out, &n), gl::LinkStatus::kOk);
  std::vector<uint8_t> flipped(out, out + n);
  flipped[3] ^= 0x10;
  if (flipped[3] == 0) flipped[3] = 0x55;
  r.send_raw(flipped);
  EXPECT_TRUE(r.receive().empty());
  // The next good request is answered, and STATUS counts what was dropped.
  r.send(gl::GetStatus{});
  const auto st = r.only<gl::Status>(r.receive());
  EXPECT_GE(st.bad_frames, 2u);
  EXPECT_EQ(st.frames_received, 1u);
  EXPECT_EQ(st.state, gl::DeviceState::kIdle);
}

TEST(LinkDevice, BadEnumValuesAndForeignIdsAreAnsweredWithTheirCode) {
  LinkRig r;
  // A SET_SCENE payload with policy = 9, forged past the packer.
  uint8_t payload[gl::kMaxPayloadSize];
  size_t size = 0;
  ASSERT_EQ(gl::pack(scene_msg(), payload, sizeof payload, &size), gl::LinkStatus::kOk);
  gl::SetScene probe;
  uint8_t bad_field = 0;
  bool found = false;
  for (size_t i = 0; i < size && !found; ++i) {
    const uint8_t saved = payload[i];
    payload[i] = 9;
    if (gl::unpack(payload, size, &probe, &bad_field) == gl::LinkStatus::kBadEnumValue)
      found = true;
    else
      payload[i] = saved;
  }
  ASSERT_TRUE(found);
  gl::FrameHeader h;
  h.msg_id = uint8_t(gl::MsgId::kSetScene);
  h.seq = 40;
  uint8_t out[gl::kMaxWireFrameSize];
  size_t n = 0;
  ASSERT_EQ(gl::encode_frame(h, payload, size, out, sizeof out, &n), gl::LinkStatus::kOk);
  r.send_raw(std::vector<uint8_t>(out, out + n));
  auto e = r.only<gl::Error>(r.receive());
  EXPECT_EQ(e.code, gl::ErrorCode::kBadEnumValue);
  EXPECT_EQ(e.request_seq, 40);
  // A device -> host id sent to the device.
  h.msg_id = uint8_t(gl::MsgId::kTelemetry);
  h.seq = 41;
  ASSERT_EQ(gl::encode_frame(h, payload, 24, out, sizeof out, &n), gl::LinkStatus::kOk);
  r.send_raw(std::vector<uint8_t>(out, out + n));
  e = r.only<gl::Error>(r.receive());
  EXPECT_EQ(e.code, gl::ErrorCode::kUnknownId);
  EXPECT_EQ(e.request_seq, 41);
}

TEST(LinkDevice, ATrialEndsWithATrialResult) {
  LinkRig r;
  r.send(scene_msg());
  gl::StartTrial t = trial_msg(11);
  const float down[6] = {0, 0, -1, 0, 0, 0};
  std::copy(down, down + 6, t.wrench);
  r.send(t);
  r.receive();
  bool done = false;
  for (uint32_t n = 0; n < 300 && !done; ++n) {
    gl::Pose p;
    p.host_time_us = n * 4000;
    r.send(p);
    for (const auto& f : r.receive()) {
      if (f.header.msg_id != uint8_t(gl::MsgId::kTrialResult)) continue;
      gl::TrialResult res;
      ASSERT_EQ(gl::unpack(f.payload.data(), f.payload.size(), &res), gl::LinkStatus::kOk);
      EXPECT_EQ(res.trial_id, 11);
      EXPECT_TRUE(res.success);
      EXPECT_NEAR(res.completion_s, 0.5f, 0.005f);
      done = true;
    }
  }
  EXPECT_TRUE(done);
  EXPECT_TRUE(r.motors.all_off());
}

// The ESP32 board serves USB and Bluetooth at once: two links, each with its own parser,
// over one application. A STOP on either link must stop a trial run from the other, and a
// frame half-received on one link must survive traffic on the other.
TEST(LinkDevice, TwoLinksShareOneApplication) {
  LinkRig usb;
  gh::MemoryStream bt_stream;
  gd::LinkDevice bt(bt_stream, usb.app, usb.info);
  gl::FrameParser bt_host{gl::Accept::kDeviceToHost};
  auto bt_send = [&](const auto& m, uint16_t s) {
    uint8_t out[gl::kMaxWireFrameSize];
    size_t n = 0;
    EXPECT_EQ(gl::write_frame(m, s, out, sizeof out, &n), gl::LinkStatus::kOk);
    bt_stream.host_send(out, n);
    bt.poll();
  };
  auto bt_receive = [&]() {
    std::vector<uint8_t> ids;
    uint8_t buf[1024];
    const size_t n = bt_stream.host_receive(buf, sizeof buf);
    for (size_t i = 0; i < n; ++i)
      if (bt_host.push(buf[i]) == gl::ParseEvent::kFrame)
        ids.push_back(bt_host.frame().header.msg_id);
    return ids;
  };

  usb.send(scene_msg());
  usb.send(trial_msg());
  gl::Pose p;
  usb.send(p);
  usb.receive();
  ASSERT_FALSE(usb.motors.all_off());

  // Half of a GET_STATUS arrives on USB, then a whole STOP on Bluetooth, then the rest.
  uint8_t out[gl::kMaxWireFrameSize];
  size_t n = 0;
  ASSERT_EQ(gl::write_frame(gl::GetStatus{}, 77, out, sizeof out, &n), gl::LinkStatus::kOk);
  usb.stream.host_send(out, n / 2);
  usb.device->poll();
  bt_send(gl::Stop{}, 9);
  EXPECT_TRUE(usb.motors.all_off());
  EXPECT_EQ(bt_receive(), std::vector<uint8_t>{uint8_t(gl::MsgId::kAck)});
  EXPECT_TRUE(usb.receive().empty());  // the STOP's answer went to the link that sent it
  usb.stream.host_send(out + n / 2, n - n / 2);
  usb.device->poll();
  const auto status = usb.only<gl::Status>(usb.receive());
  EXPECT_EQ(status.state, gl::DeviceState::kStopped);
  EXPECT_EQ(status.bad_frames, 0u);
}
