// The link with a host-less runner and its store (docs/protocol.md "Safety"): the requests
// that write the store block the loop, so they are refused while anything drives the
// motors, no store write ever happens with the motors on, and an ERROR or a dropped frame
// during a host-less run's vibration pattern stops the run, so its motors stay off.
#include <gtest/gtest.h>

#include <cstring>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "common/hand_scenes.h"
#include "graspguide_device/fake_storage.h"
#include "graspguide_device/link_device.h"
#include "graspguide_hal/fake_hal.h"

namespace gd = graspguide::device;
namespace gl = graspguide::link;
namespace gh = graspguide::hal;

namespace {

constexpr uint32_t kMs = 1000;
constexpr uint32_t kStoreBytes = 64 * 1024;
constexpr float kG = 9.80665f;

// The rig's store: RAM, and a count of the writes made while any motor was on.
class WatchedStorage final : public gd::NvStorage {
 public:
  WatchedStorage(gd::NvStorage& inner, const gh::RecordingMotors& motors)
      : inner_(inner), motors_(motors) {}
  uint32_t size_bytes() const override { return inner_.size_bytes(); }
  bool read(uint32_t offset, uint8_t* out, uint32_t n) override {
    return inner_.read(offset, out, n);
  }
  bool write(uint32_t offset, const uint8_t* data, uint32_t n) override {
    ++writes;
    if (!motors_.all_off()) ++writes_with_motors_on;
    return inner_.write(offset, data, n);
  }
  uint32_t writes = 0, writes_with_motors_on = 0;

 private:
  gd::NvStorage& inner_;
  const gh::RecordingMotors& motors_;
};

gd::DeviceInfo sim_info() {
  gd::DeviceInfo i;
  i.board = "test";
  i.capabilities =
      uint8_t(gl::kCapabilityFullSolve | gl::kCapabilityHostless | gl::kCapabilitySimMessages);
  return i;
}

struct Rig {
  gh::FakeClock clock;
  gh::RecordingMotors motors;
  std::unique_ptr<gd::RamStorage<kStoreBytes>> ram =
      std::make_unique<gd::RamStorage<kStoreBytes>>();
  WatchedStorage store{*ram, motors};
  gd::Application app{motors, clock};
  gd::HostlessRunner runner{motors, clock, store, gh::ImuOutput::kSixAxis, 8 * kG, 34.9f};
  gh::MemoryStream stream;
  gd::LinkDevice device{stream, app, sim_info(), nullptr, &runner};
  gl::FrameParser host{gl::Accept::kDeviceToHost};
  uint16_t seq = 100;

  Rig() { EXPECT_EQ(runner.boot(), gd::StoreStatus::kOk); }

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
  void poll_after(uint32_t dt_us) {
    clock.advance_us(dt_us);
    device.poll();
  }

  // Every frame the device sent since the last call: (id, payload).
  std::vector<std::pair<uint8_t, std::vector<uint8_t>>> received() {
    std::vector<std::pair<uint8_t, std::vector<uint8_t>>> out;
    uint8_t buf[4096];
    size_t n;
    while ((n = stream.host_receive(buf, sizeof buf)) > 0)
      for (size_t i = 0; i < n; ++i)
        if (host.push(buf[i]) == gl::ParseEvent::kFrame) {
          const auto& f = host.frame();
          out.emplace_back(f.header.msg_id,
                           std::vector<uint8_t>(f.payload, f.payload + f.payload_size));
        }
    return out;
  }
  template <class Msg>
  std::vector<Msg> all() {
    std::vector<Msg> out;
    for (const auto& f : received())
      if (f.first == uint8_t(Msg::kId)) {
        Msg m;
        EXPECT_EQ(gl::unpack(f.second.data(), f.second.size(), &m), gl::LinkStatus::kOk);
        out.push_back(m);
      }
    return out;
  }
  // The one answer (ACK or ERROR) to the request just sent: true for ACK, *code for ERROR.
  bool acked(gl::ErrorCode* code = nullptr) {
    bool ack = false;
    int answers = 0;
    for (const auto& f : received()) {
      if (f.first == uint8_t(gl::MsgId::kAck)) {
        ack = true;
        ++answers;
      } else if (f.first == uint8_t(gl::MsgId::kError)) {
        gl::Error e;
        EXPECT_EQ(gl::unpack(f.second.data(), f.second.size(), &e), gl::LinkStatus::kOk);
        if (code) *code = e.code;
        ++answers;
      }
    }
    EXPECT_EQ(answers, 1);
    return ack;
  }
  gl::LogInfo log_info() {
    send(gl::LogInfoGet{});
    const auto infos = all<gl::LogInfo>();
    EXPECT_EQ(infos.size(), 1u);
    return infos.empty() ? gl::LogInfo{} : infos.back();
  }
};

gl::PlanBegin begin_msg(uint16_t trials, float rest_s = 0, float timeout_s = 5) {
  gl::PlanBegin m;
  std::strcpy(m.participant, "U1");
  m.simulated = true;
  m.trial_count = trials;
  m.rest_s = rest_s;
  m.timeout_s = timeout_s;
  const auto c = graspguide_test::nominal_hand();
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) {
      if (i < 3) m.hand_k3[i][j] = float(c(j, i));
      m.hand_k4[i][j] = float(c(j, i));
    }
  return m;
}

gl::PlanTrial trial_msg(uint16_t position) {
  gl::PlanTrial m;
  m.position = position;
  m.trial_index = uint16_t(position + 1);
  m.session = 1;
  m.session_trial = uint8_t(position + 1);
  m.k = 3;
  m.wrench_number = 1;
  const float w[6] = {0.4f, -1.0f, 0.3f, 0, 0, 0};
  std::memcpy(m.wrench, w, sizeof m.wrench);
  return m;
}

gl::LogErase erase_msg() {
  gl::LogErase m;
  m.key = gl::kLogEraseKey;
  return m;
}

void upload(Rig& r, uint16_t trials, float rest_s = 0, float timeout_s = 5) {
  r.send(begin_msg(trials, rest_s, timeout_s));
  ASSERT_TRUE(r.acked());
  for (uint16_t i = 0; i < trials; ++i) {
    r.send(trial_msg(i));
    ASSERT_TRUE(r.acked());
  }
  gl::PlanCommit c;
  c.trial_count = trials;
  r.send(c);
  ASSERT_TRUE(r.acked());
}

// One finished trial in the log, so that an erase has something to lose.
void one_record(Rig& r) {
  upload(r, 2, 0, 1);
  r.send(gl::HostlessRun{});
  ASSERT_TRUE(r.acked());
  r.poll_after(kMs);  // the rest (0 s) ends, the ready pattern plays
  r.poll_after(700 * kMs);
  ASSERT_EQ(r.runner.phase(), gd::RunPhase::kWaitButton);
  r.runner.on_button(true, r.clock.now_us());
  r.poll_after(1100 * kMs);  // no samples: the trial times out and is logged
  r.send(gl::Stop{});
  r.received();
  ASSERT_EQ(r.runner.log().records(), 1);
}

// The ways something drives the motors (or is about to) when a storage request arrives.
struct Driver {
  const char* name;
  std::function<void(Rig&)> start;
  bool hostless = false;  // a run needs the stored plan, not one being uploaded
};

std::vector<Driver> drivers() {
  gl::SetScene scene;
  scene.k = 4;
  const auto c = graspguide_test::nominal_hand();
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) scene.contacts[i][j] = float(c(j, i));
  gl::StartTrial start;
  start.trial_id = 7;
  const float w[6] = {0.4f, -1.0f, 0.3f, 0, 0, 0};
  std::memcpy(start.wrench, w, sizeof start.wrench);
  gl::Pose tilted;
  tilted.host_time_us = 1000;
  tilted.quat_wxyz[0] = 0.9394f;
  tilted.quat_wxyz[1] = 0.1125f;
  tilted.quat_wxyz[2] = 0.2250f;
  tilted.quat_wxyz[3] = -0.2312f;
  return {
      {"a tracker trial's POSE",
       [=](Rig& r) {
         r.send(scene);
         r.send(start);
         r.send(tilted);
         r.received();
         ASSERT_FALSE(r.motors.all_off());
       }},
      {"a tracker trial before its first POSE",
       [=](Rig& r) {
         r.send(scene);
         r.send(start);
         r.received();
         ASSERT_EQ(r.app.state(), gd::DeviceState::kTrialRunning);
       }},
      {"SET_MOTORS",
       [](Rig& r) {
         gl::SetMotors m;
         m.pwm[0] = m.pwm[1] = 180;
         r.send(m);
         ASSERT_TRUE(r.acked());
         ASSERT_FALSE(r.motors.all_off());
       }},
      {"a host-less run's ready pattern",
       [](Rig& r) {
         r.send(gl::HostlessRun{});
         ASSERT_TRUE(r.acked());
         r.poll_after(kMs);
         r.received();
         ASSERT_EQ(r.runner.phase(), gd::RunPhase::kReadyPattern);
         ASSERT_FALSE(r.motors.all_off());
       },
       true},
  };
}

struct StorageRequest {
  const char* name;
  std::function<void(Rig&)> send;
};

std::vector<StorageRequest> storage_requests() {
  return {
      {"PLAN_BEGIN", [](Rig& r) { r.send(begin_msg(2)); }},
      {"PLAN_TRIAL", [](Rig& r) { r.send(trial_msg(0)); }},
      {"PLAN_COMMIT",
       [](Rig& r) {
         gl::PlanCommit c;
         c.trial_count = 2;
         r.send(c);
       }},
      {"LOG_ERASE", [](Rig& r) { r.send(erase_msg()); }},
  };
}

}  // namespace

TEST(LinkHostless, StorageRequestsAreRefusedWhileAnythingDrivesTheMotors) {
  for (const Driver& d : drivers())
    for (const StorageRequest& q : storage_requests()) {
      SCOPED_TRACE(std::string(q.name) + " during " + d.name);
      Rig r;
      one_record(r);
      if (!d.hostless) {  // a plan upload under way, so that PLAN_TRIAL and PLAN_COMMIT count
        r.send(begin_msg(2));
        ASSERT_TRUE(r.acked());
        r.send(trial_msg(0));
        ASSERT_TRUE(r.acked());
        r.send(trial_msg(1));
        ASSERT_TRUE(r.acked());
      }
      d.start(r);
      const uint32_t writes = r.store.writes;
      q.send(r);
      gl::ErrorCode code = gl::ErrorCode::kOk;
      EXPECT_FALSE(r.acked(&code));
      EXPECT_EQ(code, gl::ErrorCode::kNotAllowedInState);
      EXPECT_TRUE(r.motors.all_off());
      EXPECT_EQ(r.store.writes, writes) << "the store was written";
      EXPECT_EQ(r.runner.log().records(), 1);
    }
}

TEST(LinkHostless, StorageRequestsAreTakenOnceTheMotorsRest) {
  Rig r;
  one_record(r);
  gl::SetMotors m;
  m.pwm[2] = 150;
  r.send(m);
  ASSERT_TRUE(r.acked());
  r.poll_after(gd::kDefaultStaleTimeoutUs);  // the watchdog turns them off
  ASSERT_TRUE(r.motors.all_off());
  r.send(erase_msg());
  EXPECT_TRUE(r.acked());
  EXPECT_EQ(r.runner.log().records(), 0);
  upload(r, 2);
  EXPECT_TRUE(r.log_info().plan_stored);
}

// Whatever the host sends, a byte reaches the store only with every motor off: a storage
// write blocks the loop, and nothing would turn them off meanwhile.
TEST(LinkHostless, NoStoreWriteHappensWithTheMotorsOn) {
  for (const Driver& d : drivers())
    for (const StorageRequest& q : storage_requests()) {
      SCOPED_TRACE(std::string(q.name) + " during " + d.name);
      Rig r;
      one_record(r);
      if (!d.hostless) {
        r.send(begin_msg(2));
        r.send(trial_msg(0));
        r.send(trial_msg(1));
        r.received();
      }
      d.start(r);
      q.send(r);
      r.received();
      EXPECT_EQ(r.store.writes_with_motors_on, 0u);
    }
}

// A pattern is played by the runner on every poll: an ERROR that only wrote the motors off
// once had them on again in the same poll. Any error now stops the run.
TEST(LinkHostless, AnErrorDuringAPatternStopsTheRunAndKeepsTheMotorsOff) {
  struct Fault {
    const char* name;
    std::function<void(Rig&)> send;
  };
  const std::vector<Fault> faults = {
      {"a refused tracker request", [](Rig& r) { r.send(gl::SetScene{}); }},
      {"an unknown id",
       [](Rig& r) {
         gl::FrameHeader h;
         h.msg_id = 0x3F;
         h.seq = 5;
         uint8_t out[gl::kMaxWireFrameSize];
         size_t n = 0;
         ASSERT_EQ(gl::encode_frame(h, nullptr, 0, out, sizeof out, &n), gl::LinkStatus::kOk);
         r.raw(std::vector<uint8_t>(out, out + n));
       }},
      {"a frame with a bad CRC",
       [](Rig& r) {
         std::vector<uint8_t> f = r.frame_of(gl::GetStatus{});
         f[2] ^= 0x40;
         r.raw(f);
       }},
  };
  for (const bool end_pattern : {false, true})
    for (const Fault& fault : faults) {
      SCOPED_TRACE(std::string(fault.name) +
                   (end_pattern ? " in the timeout pattern" : " in the ready pattern"));
      Rig r;
      upload(r, 2, 0, 1);
      r.send(gl::HostlessRun{});
      ASSERT_TRUE(r.acked());
      r.poll_after(kMs);
      if (end_pattern) {
        r.poll_after(700 * kMs);
        r.runner.on_button(true, r.clock.now_us());
        r.poll_after(1010 * kMs);
        ASSERT_EQ(r.runner.phase(), gd::RunPhase::kEndPattern);
        r.poll_after(kMs);
      }
      ASSERT_FALSE(r.motors.all_off());
      r.received();
      fault.send(r);
      EXPECT_TRUE(r.motors.all_off()) << "the fault's own poll";
      for (int i = 0; i < 10; ++i) {
        r.poll_after(20 * kMs);
        EXPECT_TRUE(r.motors.all_off()) << "poll " << i << " after the fault";
      }
      EXPECT_FALSE(r.log_info().running);
      // The host starts it again, from the first trial without a record.
      r.send(gl::HostlessRun{});
      EXPECT_TRUE(r.acked());
    }
}

// The fuzzer found a sample whose TELEMETRY said 0 while the motors showed 200: the rest
// ended in the sample's own tick, and the ready pattern's first pulse waited for the next.
TEST(LinkHostless, ASamplesTelemetryShowsThePatternThatBeganWithIt) {
  Rig r;
  upload(r, 2, 0.01f);
  r.send(gl::HostlessRun{});
  ASSERT_TRUE(r.acked());
  ASSERT_EQ(r.runner.phase(), gd::RunPhase::kRest);
  r.clock.advance_us(20 * kMs);  // past the rest, with no poll in between
  gl::SimImuSample s;
  s.time_us = r.clock.now_us();
  s.accel_mps2[2] = kG;
  r.send(s);
  const auto tel = r.all<gl::Telemetry>();
  ASSERT_EQ(tel.size(), 1u);
  EXPECT_EQ(r.runner.phase(), gd::RunPhase::kReadyPattern);
  EXPECT_FALSE(r.motors.all_off());
  for (int i = 0; i < graspguide::kMaxContacts; ++i)
    EXPECT_EQ(tel[0].pwm[i], r.motors.last().duty[i]) << "motor " << i;
}
