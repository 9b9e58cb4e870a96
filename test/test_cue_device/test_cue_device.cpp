// The per-frame-only device (lib/graspguide_cue_device) against the references it must
// agree with: graspguide_link's parser and writer (C++17) for every byte on the wire, the
// full-solve LinkDevice for every answer and, after the host's SET_POSTURE from
// graspguide::Guidance, for the PWM of the same pose stream.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "common/hand_scenes.h"
#include "graspguide_cue_device.h"
#include "graspguide_device/link_device.h"
#include "graspguide_hal/fake_hal.h"

namespace gg = graspguide;
namespace gd = graspguide::device;
namespace gl = graspguide::link;
namespace gfd = graspguide::cue_device;
namespace gh = graspguide::hal;

namespace {

struct Received {
  gl::FrameHeader header;
  std::vector<uint8_t> payload;
};

class BoardStream final : public gh::ByteStream {
 public:
  size_t read(uint8_t* buffer, size_t capacity) override {
    size_t n = 0;
    while (n < capacity && at_ < in_.size()) buffer[n++] = in_[at_++];
    return n;
  }
  size_t write(const uint8_t* data, size_t length) override {
    out_.insert(out_.end(), data, data + length);
    return length;
  }
  void host_send(const std::vector<uint8_t>& bytes) {
    in_.insert(in_.end(), bytes.begin(), bytes.end());
  }
  std::vector<uint8_t> host_receive() {
    std::vector<uint8_t> out;
    out.swap(out_);
    return out;
  }

 private:
  std::vector<uint8_t> in_, out_;
  size_t at_ = 0;
};

// What the host sends and reads, written and parsed by graspguide_link: the reference.
struct Host {
  gl::FrameParser parser{gl::Accept::kDeviceToHost};
  gl::SequenceCounter seq;

  template <class Msg>
  std::vector<uint8_t> frame(const Msg& m, uint16_t* s) {
    uint8_t out[gl::kMaxWireFrameSize];
    size_t n = 0;
    *s = seq.next();
    EXPECT_EQ(gl::write_frame(m, *s, out, sizeof out, &n), gl::LinkStatus::kOk);
    return std::vector<uint8_t>(out, out + n);
  }

  std::vector<Received> parse(const std::vector<uint8_t>& bytes) {
    std::vector<Received> frames;
    for (uint8_t b : bytes) {
      const gl::ParseEvent e = parser.push(b);
      EXPECT_TRUE(e == gl::ParseEvent::kNone || e == gl::ParseEvent::kFrame)
          << "the device wrote a frame graspguide_link rejects: " << gl::parse_event_name(e);
      if (e == gl::ParseEvent::kFrame) {
        const auto& f = parser.frame();
        frames.push_back({f.header, std::vector<uint8_t>(f.payload, f.payload + f.payload_size)});
      }
    }
    return frames;
  }
};

struct BoardRig {
  BoardStream stream;
  gh::RecordingMotors motors;
  gh::FakeClock clock;
  gfd::CueDevice device{stream, motors, clock, gfd::DeviceInfo{}};
  Host host;

  template <class Msg>
  uint16_t send(const Msg& m) {
    uint16_t s = 0;
    send_raw(host.frame(m, &s));
    return s;
  }
  void send_raw(const std::vector<uint8_t>& bytes) {
    stream.host_send(bytes);
    device.poll();
  }
  std::vector<Received> receive() { return host.parse(stream.host_receive()); }
  template <class Msg>
  std::vector<Received> receive_after(const Msg& m) {
    send(m);
    return receive();
  }
  void advance_us(uint32_t dt) {
    clock.advance_us(dt);
    device.poll();
  }
};

struct LinkRig {
  gh::FakeClock clock;
  gh::RecordingMotors motors;
  gd::Application app{motors, clock};
  gh::MemoryStream stream;
  gd::DeviceInfo info;
  std::unique_ptr<gd::LinkDevice> device;
  Host host;

  LinkRig() { device = std::make_unique<gd::LinkDevice>(stream, app, info); }

  template <class Msg>
  uint16_t send(const Msg& m) {
    uint16_t s = 0;
    send_raw(host.frame(m, &s));
    return s;
  }
  void send_raw(const std::vector<uint8_t>& bytes) {
    stream.host_send(bytes.data(), bytes.size());
    device->poll();
  }
  std::vector<Received> receive() {
    uint8_t buf[4096];
    const size_t n = stream.host_receive(buf, sizeof buf);
    return host.parse(std::vector<uint8_t>(buf, buf + n));
  }
  template <class Msg>
  std::vector<Received> receive_after(const Msg& m) {
    send(m);
    return receive();
  }
  void advance_us(uint32_t dt) {
    clock.advance_us(dt);
    device->poll();
  }
};

template <class Msg>
Msg only(const std::vector<Received>& frames) {
  EXPECT_EQ(frames.size(), 1u);
  Msg m;
  if (frames.empty()) return m;
  EXPECT_EQ(frames[0].header.msg_id, uint8_t(Msg::kId))
      << gl::message_name(frames[0].header.msg_id);
  EXPECT_EQ(gl::unpack(frames[0].payload.data(), frames[0].payload.size(), &m),
            gl::LinkStatus::kOk);
  return m;
}

// The schema's index of a SET_POSTURE field, found by name in graspguide_link's field list.
uint8_t posture_field(const char* name) {
  uint8_t i = 0, found = 0xFF;
  gl::for_each_field(gl::SetPosture{}, [&](const char* n, const auto&) {
    if (std::strcmp(n, name) == 0) found = i;
    ++i;
  });
  EXPECT_NE(found, 0xFF) << name;
  return found;
}

// A scene both ends see alike: the SET_SCENE a full-solve device gets, and the posture the
// host solves from exactly those float32 values.
struct Case {
  gl::SetScene scene;
  gl::StartTrial start;
};

Case random_case(std::mt19937_64& rng, int k, gl::Mode mode) {
  const auto rs = graspguide_test::random_scene(rng, k);
  Case c;
  c.scene.k = uint8_t(k);
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) c.scene.contacts[i][j] = float(rs.contacts(j, i));
  c.scene.mode = mode;
  c.scene.policy = gl::Policy::kF;
  c.scene.constraints = gl::ConstraintModel::kPaper;
  c.start.trial_id = 7;
  for (int j = 0; j < 6; ++j) c.start.wrench[j] = float(rs.wrench(j));
  return c;
}

// The host's side of a per-frame board: the core solves the posture once.
bool solve_posture(const gl::SetScene& m, const gl::StartTrial& start, gl::SetPosture* out) {
  gg::Scene<gg::Real> scene;
  scene.k = m.k;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) scene.contacts(j, i) = m.contacts[i][j];
  scene.y_axis = gg::Vec3<gg::Real>(m.y_axis[0], m.y_axis[1], m.y_axis[2]);
  scene.constraints = static_cast<gg::ConstraintModel>(m.constraints);
  scene.policy = static_cast<gg::Policy>(m.policy);
  scene.mode = static_cast<gg::Mode>(m.mode);
  gg::Vec6<gg::Real> w;
  for (int j = 0; j < 6; ++j) w(j) = start.wrench[j];
  gg::Guidance<gg::Real> g;
  gg::FrameResult<gg::Real> frame;
  if (g.set_scene(scene) != gg::Status::kOk || g.set_wrench(w) != gg::Status::kOk ||
      g.update(Eigen::Matrix<gg::Real, 4, 1>(1, 0, 0, 0), frame) != gg::Status::kOk)
    return false;
  out->k = m.k;
  out->mode = m.mode;
  for (int i = 0; i < 4; ++i) out->levels[i] = float(std::abs(g.grasp().levels(i)));
  for (int j = 0; j < 3; ++j) out->force_unit[j] = float(g.grasp().force_unit(j));
  std::memcpy(out->wrench, start.wrench, sizeof out->wrench);
  out->threshold_deg = m.threshold_deg;
  out->hold_s = m.hold_s;
  out->timeout_s = m.timeout_s;
  return true;
}

gl::SetPosture valid_posture() {
  std::mt19937_64 rng(3);
  gl::SetPosture p;
  for (;;) {
    const Case c = random_case(rng, 4, gl::Mode::kV);
    if (solve_posture(c.scene, c.start, &p)) return p;
  }
}

gl::StartTrial start_for(const gl::SetPosture& p, uint16_t id = 1) {
  gl::StartTrial s;
  s.trial_id = id;
  std::memcpy(s.wrench, p.wrench, sizeof s.wrench);
  return s;
}

gl::Error expect_error(const std::vector<Received>& frames, gl::ErrorCode code) {
  const gl::Error e = only<gl::Error>(frames);
  EXPECT_EQ(e.code, code) << gl::enum_name(e.code);
  return e;
}

template <class... M, class Fn>
void for_each_message(gl::MessageList<M...>, Fn&& fn) {
  (fn(M{}), ...);
}

}  // namespace

TEST(CueDevice, MotorsAreOffFromBoot) {
  BoardRig r;
  EXPECT_GE(r.motors.writes(), 1u);
  EXPECT_TRUE(r.motors.all_off());
}

TEST(CueDevice, HelloSaysPerFrameOnlyFloatAndPromini) {
  BoardRig r;
  const uint16_t s = r.send(gl::Hello{});
  const auto reply = only<gl::HelloReply>(r.receive());
  EXPECT_EQ(reply.request_seq, s);
  EXPECT_EQ(reply.protocol_version, gl::kProtocolVersion);
  EXPECT_EQ(reply.capabilities, gl::kCapabilityPerFrame);
  EXPECT_EQ(reply.scalar, sizeof(float));
  EXPECT_EQ(reply.max_contacts, gl::kMaxContacts);
  EXPECT_STREQ(std::string(reply.board, sizeof reply.board).c_str(), "promini");
}

// Every host -> device message with its default fields, on a fresh device: the same answer
// as the full-solve device, except what only it can do.
TEST(CueDevice, AnswersEveryRequestAsTheFullSolveDeviceDoes) {
  auto each = [](auto message) {
    using Msg = decltype(message);
    if (!gl::is_host_to_device_id(uint8_t(Msg::kId))) return;
    BoardRig board;
    LinkRig full;
    board.send(message);
    full.send(message);
    const auto b = board.receive();
    const auto f = full.receive();
    ASSERT_EQ(b.size(), 1u) << Msg::kName;
    ASSERT_EQ(f.size(), 1u) << Msg::kName;
    if (Msg::kId == gl::MsgId::kSetScene) {
      const auto e = expect_error(b, gl::ErrorCode::kPerFrameOnly);
      EXPECT_EQ(e.detail, uint8_t(gl::MsgId::kSetScene));
      return;
    }
    if (Msg::kId == gl::MsgId::kSetPosture) {
      // The default posture has no level on: nothing to display.
      const auto e = expect_error(b, gl::ErrorCode::kBadConfig);
      EXPECT_EQ(e.detail, posture_field("levels"));
      EXPECT_EQ(only<gl::Error>(f).code, gl::ErrorCode::kUnknownId);
      return;
    }
    EXPECT_EQ(b[0].header.msg_id, f[0].header.msg_id) << Msg::kName;
    if (b[0].header.msg_id == uint8_t(gl::MsgId::kError)) {
      const auto eb = only<gl::Error>(b), ef = only<gl::Error>(f);
      EXPECT_EQ(eb.code, ef.code) << Msg::kName << ": " << gl::enum_name(eb.code);
      EXPECT_EQ(eb.detail, ef.detail) << Msg::kName;
    } else if (b[0].header.msg_id == uint8_t(gl::MsgId::kStatus)) {
      EXPECT_EQ(b[0].payload, f[0].payload);
    }
  };
  for_each_message(gl::AllMessages{}, each);
}

// The same trial on both devices: SET_SCENE + START_TRIAL on the full-solve one, the host's
// SET_POSTURE + START_TRIAL on this one, then the same POSE stream.
TEST(CueDevice, ThePoseStreamGivesTheFullSolveDevicesPwmWithinOneCount) {
  std::mt19937_64 rng(15);
  int compared = 0, driven = 0, succeeded = 0, timed_out = 0;
  for (int n = 0; n < 24; ++n) {
    const int k = 3 + n % 2;
    const gl::Mode mode = (n / 2) % 2 ? gl::Mode::kV : gl::Mode::kC;
    Case c = random_case(rng, k, mode);
    // Short enough that some trials end by timeout, loose enough that others succeed.
    c.scene.threshold_deg = n % 3 == 0 ? 179.0f : 20.0f;
    c.scene.hold_s = 0.02f;
    c.scene.timeout_s = 0.1f;
    gl::SetPosture posture;
    if (!solve_posture(c.scene, c.start, &posture)) continue;
    BoardRig board;
    LinkRig full;
    const uint16_t posture_seq = board.send(posture);
    EXPECT_EQ(only<gl::Ack>(board.receive()).request_seq, posture_seq);
    only<gl::Ack>(full.receive_after(c.scene));
    only<gl::Ack>(board.receive_after(c.start));
    only<gl::Ack>(full.receive_after(c.start));
    bool ended = false;
    for (int p = 0; p < 40 && !ended; ++p) {
      const auto rs = graspguide_test::random_scene(rng, k);
      gl::Pose pose;
      pose.host_time_us = uint32_t(1000000 + p * 4000);
      for (int j = 0; j < 4; ++j) pose.quat_wxyz[j] = float(rs.orientation(j));
      board.clock.advance_us(4000);
      full.clock.advance_us(4000);
      const auto b = board.receive_after(pose);
      const auto f = full.receive_after(pose);
      ASSERT_EQ(b.size(), f.size()) << n << "/" << p;
      ASSERT_GE(b.size(), 1u);
      const auto tb = only<gl::Telemetry>({b[0]});
      const auto tf = only<gl::Telemetry>({f[0]});
      EXPECT_EQ(tb.solver_status, tf.solver_status);
      EXPECT_EQ(tb.flags & gl::kTelemetryFlagTrialRunning,
                tf.flags & gl::kTelemetryFlagTrialRunning)
          << n << "/" << p;
      EXPECT_NEAR(tb.error_deg, tf.error_deg, 0.01) << n << "/" << p;
      EXPECT_NEAR(tb.alpha, tf.alpha, 0.01) << n << "/" << p;
      for (int i = 0; i < 4; ++i) {
        EXPECT_NEAR(tb.pwm[i], tf.pwm[i], 1) << n << "/" << p << " motor " << i;
        EXPECT_NEAR(board.motors.last().duty[i], full.motors.last().duty[i], 1);
      }
      ++compared;
      driven += tf.pwm[0] + tf.pwm[1] + tf.pwm[2] + tf.pwm[3] > 0;
      if (b.size() == 2) {
        ended = true;
        const auto rb = only<gl::TrialResult>({b[1]});
        const auto rf = only<gl::TrialResult>({f[1]});
        EXPECT_EQ(rb.trial_id, rf.trial_id);
        EXPECT_EQ(rb.success, rf.success);
        EXPECT_FLOAT_EQ(rb.completion_s, rf.completion_s);
        EXPECT_FLOAT_EQ(rb.first_entry_s, rf.first_entry_s);
        EXPECT_NEAR(rb.final_error_deg, rf.final_error_deg, 0.01);
        EXPECT_TRUE(board.motors.all_off());
        (rf.success ? succeeded : timed_out) += 1;
      }
    }
    EXPECT_TRUE(ended) << n;
  }
  // Not a vacuous agreement: most poses drive motors, and trials end both ways.
  EXPECT_GE(compared, 200);
  EXPECT_GE(driven, compared / 2);
  EXPECT_GT(succeeded, 0);
  EXPECT_GT(timed_out, 0);
}

TEST(CueDevice, SetPostureRefusesEachBadFieldByItsSchemaIndexAndStopsTheMotors) {
  struct Bad {
    const char* field;
    void (*spoil)(gl::SetPosture&);
  };
  const Bad cases[] = {
      {"k", [](gl::SetPosture& p) { p.k = 5; }},
      {"k", [](gl::SetPosture& p) { p.k = 2; }},
      {"levels", [](gl::SetPosture& p) { p.levels[0] = NAN; }},
      {"levels", [](gl::SetPosture& p) { p.levels[1] = 1.5f; }},
      {"levels", [](gl::SetPosture& p) { p.levels[2] = -0.5f; }},
      {"levels", [](gl::SetPosture& p) { p.k = 3, p.levels[3] = 0.5f; }},
      {"force_unit", [](gl::SetPosture& p) { p.force_unit[0] *= 2.0f; }},
      {"force_unit", [](gl::SetPosture& p) { p.force_unit[2] = INFINITY; }},
      {"wrench", [](gl::SetPosture& p) { p.wrench[4] = NAN; }},
      {"threshold_deg", [](gl::SetPosture& p) { p.threshold_deg = 181.0f; }},
      {"hold_s", [](gl::SetPosture& p) { p.hold_s = -1.0f; }},
      {"hold_s", [](gl::SetPosture& p) { p.hold_s = 50.0f, p.timeout_s = 10.0f; }},
      {"timeout_s", [](gl::SetPosture& p) { p.timeout_s = 0.0f; }},
  };
  for (const Bad& bad : cases) {
    BoardRig r;
    gl::SetMotors on;
    on.pwm[0] = 200;
    r.send(on);
    only<gl::Ack>(r.receive());
    ASSERT_FALSE(r.motors.all_off());
    gl::SetPosture p = valid_posture();
    if (p.k == 3) p.levels[3] = 0.0f;
    bad.spoil(p);
    const auto e = expect_error(r.receive_after(p), gl::ErrorCode::kBadConfig);
    EXPECT_EQ(e.detail, posture_field(bad.field)) << bad.field;
    EXPECT_TRUE(r.motors.all_off()) << bad.field;
    // The posture was not taken.
    expect_error(r.receive_after(start_for(p)), gl::ErrorCode::kNoScene);
  }
  BoardRig r;
  gl::SetPosture p = valid_posture();
  p.mode = static_cast<gl::Mode>(7);
  uint8_t raw[gl::kMaxWireFrameSize];
  uint8_t payload[gl::SetPosture::kPayloadSize];
  size_t n = 0;
  p.mode = gl::Mode::kV;
  ASSERT_EQ(gl::pack(p, payload, sizeof payload, &n), gl::LinkStatus::kOk);
  payload[posture_field("mode")] = 7;  // k is one byte, so mode's byte is its index
  gl::FrameHeader h;
  h.msg_id = uint8_t(gl::MsgId::kSetPosture);
  ASSERT_EQ(gl::encode_frame(h, payload, n, raw, sizeof raw, &n), gl::LinkStatus::kOk);
  r.send_raw(std::vector<uint8_t>(raw, raw + n));
  EXPECT_EQ(expect_error(r.receive(), gl::ErrorCode::kBadEnumValue).detail, posture_field("mode"));
}

TEST(CueDevice, StartTrialNeedsThePosturesExactWrench) {
  BoardRig r;
  const gl::SetPosture p = valid_posture();
  expect_error(r.receive_after(start_for(p)), gl::ErrorCode::kNoScene);
  only<gl::Ack>(r.receive_after(p));
  gl::StartTrial other = start_for(p);
  other.wrench[2] = std::nextafter(other.wrench[2], 1e9f);  // one ulp away
  const auto e = expect_error(r.receive_after(other), gl::ErrorCode::kPostureMismatch);
  EXPECT_EQ(e.detail, 0);
  only<gl::Ack>(r.receive_after(start_for(p)));
  EXPECT_EQ(r.device.state(), gfd::CueDevice::State::kTrialRunning);
  // Refused while it runs, as SET_SCENE is on the full-solve device.
  expect_error(r.receive_after(p), gl::ErrorCode::kNotAllowedInState);
}

TEST(CueDevice, PoseContactsNeedTheFullSolve) {
  BoardRig r;
  const gl::SetPosture p = valid_posture();
  only<gl::Ack>(r.receive_after(p));
  only<gl::Ack>(r.receive_after(start_for(p)));
  gl::Pose pose;
  pose.has_contacts = true;
  const auto e = expect_error(r.receive_after(pose), gl::ErrorCode::kPerFrameOnly);
  EXPECT_EQ(e.detail, uint8_t(gl::MsgId::kPose));
  EXPECT_TRUE(r.motors.all_off());
}

TEST(CueDevice, TheWatchdogStopsTheMotorsWhenPosesStop) {
  BoardRig r;
  const gl::SetPosture p = valid_posture();
  only<gl::Ack>(r.receive_after(p));
  only<gl::Ack>(r.receive_after(start_for(p)));
  // Tilted so that at least one motor runs.
  gl::Pose pose;
  pose.quat_wxyz[0] = 0.8f;
  pose.quat_wxyz[1] = 0.6f;
  r.receive_after(pose);
  ASSERT_FALSE(r.motors.all_off());
  const uint32_t timeout_us = gl::kPoseWatchdogMs * 1000u;
  r.advance_us(timeout_us - 1);
  EXPECT_FALSE(r.motors.all_off());
  r.advance_us(1);
  EXPECT_TRUE(r.motors.all_off());
  EXPECT_EQ(r.device.stale_events(), 1u);
  const auto s = only<gl::Status>(r.receive_after(gl::GetStatus{}));
  EXPECT_EQ(s.stale_events, 1u);
  EXPECT_EQ(s.state, gl::DeviceState::kTrialRunning);
}

TEST(CueDevice, TheTrialEndsOnTheBoardsClockWhenPoseTimesFreeze) {
  BoardRig r;
  gl::SetPosture p = valid_posture();
  p.threshold_deg = 0.0f;
  p.hold_s = 0.0f;
  p.timeout_s = 1.0f;
  only<gl::Ack>(r.receive_after(p));
  only<gl::Ack>(r.receive_after(start_for(p, 9)));
  gl::Pose pose;
  pose.quat_wxyz[0] = 0.8f;
  pose.quat_wxyz[1] = 0.6f;
  r.receive_after(pose);
  r.advance_us(uint32_t(1e6 + gfd::kTrialClockSlackUs) - 1);
  EXPECT_TRUE(r.receive().empty());
  r.advance_us(1);
  const auto result = only<gl::TrialResult>(r.receive());
  EXPECT_EQ(result.trial_id, 9);
  EXPECT_FALSE(result.success);
  EXPECT_FLOAT_EQ(result.completion_s, 1.0f);
  EXPECT_EQ(r.device.state(), gfd::CueDevice::State::kSceneSet);
}

TEST(CueDevice, StopEndsTheTrialAndTheMotorsAtOnce) {
  BoardRig r;
  const gl::SetPosture p = valid_posture();
  only<gl::Ack>(r.receive_after(p));
  only<gl::Ack>(r.receive_after(start_for(p)));
  gl::Pose pose;
  pose.quat_wxyz[0] = 0.8f;
  pose.quat_wxyz[1] = 0.6f;
  r.receive_after(pose);
  ASSERT_FALSE(r.motors.all_off());
  only<gl::Ack>(r.receive_after(gl::Stop{}));
  EXPECT_TRUE(r.motors.all_off());
  EXPECT_EQ(r.device.state(), gfd::CueDevice::State::kStopped);
  // The posture stays: a new trial needs no new SET_POSTURE.
  only<gl::Ack>(r.receive_after(start_for(p)));
}

// Garbage, cut frames, frames of every size and ids up to the schema's largest, fed to this
// parser and to graspguide_link's: the same verdict at every byte, the same header and
// payload for every trusted one.
TEST(CueDevice, TheParserAgreesWithGraspguideLinkOnAnyByteStream) {
  std::mt19937_64 rng(99);
  std::uniform_int_distribution<int> byte(0, 255), pick(0, 9);
  for (int round = 0; round < 200; ++round) {
    std::vector<uint8_t> stream;
    for (int piece = 0; piece < 30; ++piece) {
      const int kind = pick(rng);
      if (kind < 4) {  // a well-formed frame of a random id and size, maybe damaged
        gl::FrameHeader h;
        h.msg_id = uint8_t(kind == 0 ? byte(rng) : byte(rng) % 0x14);
        h.seq = uint16_t(byte(rng) | (byte(rng) << 8));
        if (kind == 1) h.version = uint8_t(byte(rng));
        size_t size = 0;
        if (!gl::payload_size_of(h.msg_id, &size) || kind == 2) size = size_t(byte(rng)) % 149;
        std::vector<uint8_t> payload(size);
        for (auto& b : payload) b = uint8_t(byte(rng) % 3 == 0 ? 0 : byte(rng));
        uint8_t out[gl::kMaxWireFrameSize];
        size_t n = 0;
        ASSERT_EQ(gl::encode_frame(h, payload.data(), size, out, sizeof out, &n),
                  gl::LinkStatus::kOk);
        if (kind == 3 && n > 2) out[size_t(byte(rng)) % (n - 1)] ^= uint8_t(1 + byte(rng) % 255);
        stream.insert(stream.end(), out, out + n);
      } else if (kind < 7) {  // noise
        for (int i = byte(rng) % 40; i > 0; --i) stream.push_back(uint8_t(byte(rng)));
      } else if (kind < 8) {  // a run longer than any frame
        for (int i = 0; i < 170 + byte(rng); ++i) stream.push_back(uint8_t(1 + byte(rng) % 255));
      } else {
        stream.push_back(0);
      }
    }
    gfd::FrameParser mine;
    gl::FrameParser reference{gl::Accept::kHostToDevice};
    for (size_t i = 0; i < stream.size(); ++i) {
      const gfd::ParseEvent a = mine.push(stream[i]);
      const gl::ParseEvent b = reference.push(stream[i]);
      ASSERT_EQ(uint8_t(a), uint8_t(b))
          << "round " << round << " byte " << i << ": " << gl::parse_event_name(b);
      if (!gl::has_trusted_header(b)) continue;
      const auto& fa = mine.frame();
      const auto& fb = reference.frame();
      EXPECT_EQ(fa.header.version, fb.header.version);
      EXPECT_EQ(fa.header.msg_id, fb.header.msg_id);
      EXPECT_EQ(fa.header.seq, fb.header.seq);
      EXPECT_EQ(fa.payload_size, fb.payload_size);
      if (fa.payload != nullptr)
        EXPECT_EQ(0, std::memcmp(fa.payload, fb.payload, fb.payload_size));
      else
        EXPECT_GT(fb.payload_size, gfd::link::kMaxAcceptedPayloadSize);
    }
    EXPECT_EQ(mine.good_frames(), reference.good_frames());
    EXPECT_EQ(mine.bad_frames(), reference.bad_frames());
  }
}

TEST(CueDevice, GarbageIsCountedAndTheNextRequestIsAnswered) {
  BoardRig r;
  LinkRig full;
  std::mt19937_64 rng(5);
  std::uniform_int_distribution<int> byte(0, 255);
  std::vector<uint8_t> junk(4000);
  for (auto& b : junk) b = uint8_t(byte(rng));
  r.send_raw(junk);
  full.send_raw(junk);
  const auto rb = r.receive();
  const auto rf = full.receive();
  ASSERT_EQ(rb.size(), rf.size());  // the rare trusted header is answered alike
  for (size_t i = 0; i < rb.size(); ++i) EXPECT_EQ(rb[i].payload, rf[i].payload);
  EXPECT_TRUE(r.motors.all_off());
  std::vector<uint8_t> hello{0};           // ends whatever the junk left open
  full.send_raw(std::vector<uint8_t>{0});  // on both, so both count what it ends
  uint16_t s = 0;
  const auto f = r.host.frame(gl::Hello{}, &s);
  hello.insert(hello.end(), f.begin(), f.end());
  r.send_raw(hello);
  EXPECT_EQ(only<gl::HelloReply>(r.receive()).request_seq, s);
  const auto status = only<gl::Status>(r.receive_after(gl::GetStatus{}));
  EXPECT_EQ(status.bad_frames, full.device->parser().bad_frames());
}

TEST(CueDevice, APartialFrameIsDroppedAfterSilence) {
  BoardRig r;
  uint16_t s = 0;
  const auto f = r.host.frame(gl::Hello{}, &s);
  r.send_raw(std::vector<uint8_t>(f.begin(), f.begin() + 3));
  r.advance_us(gh::kPartialFrameTimeoutUs);
  r.send_raw(r.host.frame(gl::Hello{}, &s));  // no leading delimiter
  EXPECT_EQ(only<gl::HelloReply>(r.receive()).request_seq, s);
}

TEST(CueDevice, BadVersionAndBadLengthAreAnsweredWithTheirDetail) {
  BoardRig r;
  gl::FrameHeader h;
  h.version = 9;
  h.msg_id = uint8_t(gl::MsgId::kHello);
  uint8_t out[64];
  size_t n = 0;
  const uint8_t payload[1] = {3};
  ASSERT_EQ(gl::encode_frame(h, payload, 1, out, sizeof out, &n), gl::LinkStatus::kOk);
  r.send_raw(std::vector<uint8_t>(out, out + n));
  EXPECT_EQ(expect_error(r.receive(), gl::ErrorCode::kBadVersion).detail, 9);
  h.version = gl::kProtocolVersion;
  h.msg_id = uint8_t(gl::MsgId::kPose);
  ASSERT_EQ(gl::encode_frame(h, payload, 1, out, sizeof out, &n), gl::LinkStatus::kOk);
  r.send_raw(std::vector<uint8_t>(out, out + n));
  EXPECT_EQ(expect_error(r.receive(), gl::ErrorCode::kBadLength).detail, uint8_t(gl::MsgId::kPose));
}
