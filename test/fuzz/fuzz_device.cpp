// libFuzzer target: the device's message handling (LinkDevice + Application, and the
// host-less runner with its plan store and results log in an in-memory store) on fake
// hardware, driven by a host whose requests, field values and timing come from the input.
// Built and run by tools/scripts/fuzz.sh (not by pio: this folder is no test_*).
//
// Input: one configuration byte (bit 0 virtual clock, bit 1 start near the u32 wrap, bit 2
// a board without the host-less runner), then operations until the input ends. An
// operation sends a well-formed request (HELLO, SET_SCENE, START_TRIAL, POSE, STOP,
// SET_MOTORS, GET_STATUS; PLAN_BEGIN, PLAN_TRIAL, PLAN_COMMIT or a whole plan upload,
// HOSTLESS_RUN, LOG_INFO_GET, LOG_READ, LOG_ERASE, SIM_IMU_SAMPLE alone or in bursts,
// SIM_BUTTON) built from a plausible template with some fields replaced by values from the
// input (any float bit pattern, NaN, inf, huge, tiny; any u32 timestamp or jump), and
// encoded by the project's write_frame so the CRC passes. Other operations advance the
// device clock, send a frame with any header and payload (right CRC, e.g. a bad enum), raw
// garbage, or hurt the store: a power cut after n bytes (a torn write), reads that fail,
// a flipped bit (flash wear), a reboot. So the fuzzer spends its time in the device, not
// in the parser (fuzz_frame_parser does that).
//
// The device reads one frame per poll(), so every answer can be tied to its request.
// Invariants (a violation prints "invariant violated: ..." and traps, a crash to libFuzzer):
//  1. no ASan or UBSan finding;
//  2. every ERROR the device sends leaves the motors off, and so does a STOP;
//  3. after the device clock ran the POSE watchdog's time with no POSE or SET_MOTORS,
//     poll() leaves the motors off;
//  4. a running trial ends (TRIAL_RESULT, ERROR or STOP) once the device clock has run
//     more than timeout_s + 1 s past its first POSE, whatever the POSE timestamps did
//     (real-time clock only: a virtual clock is the POSE timestamps);
//  6. the host-less runner and its store: no store write ever happens with a motor on (a
//     write blocks the loop); PLAN_* and LOG_ERASE are acknowledged only when no trial ran,
//     no motor was on and no run went on; an ERROR or a dropped frame ends a run and leaves
//     the motors off; a host-less trial without a sample for the IMU's stale time has its
//     motors off; an acknowledged commit leaves a stored plan, an acknowledged erase an
//     empty log; LOG_INFO tells the runner's state; LOG_RECORD echoes its index; a
//     host-less TRIAL_RESULT's completion is within [0, the plan's timeout_s]; a reboot
//     (on any store) leaves the motors off;
//  5. the protocol as docs/protocol.md states it: every frame the device writes parses;
//     each request with a trustworthy header gets exactly one answer of its kind with its
//     seq; TELEMETRY shows the PWM the motors got, a solver failure means motors off, and
//     its trial_running flag says whether the trial still runs (the host ends on a clear one);
//     TRIAL_RESULT names the running trial, ends it and reports 0 <= completion <= timeout;
//     STATUS tells the state and the parser's counters; an accepted scene's trial fields
//     are within their documented ranges.
//
// With GRASPGUIDE_FUZZ_WRITE_SEEDS=<dir> the binary writes its seed inputs there and exits.
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "common/hand_scenes.h"
#include "graspguide_device/fake_storage.h"
#include "graspguide_device/link_device.h"
#include "graspguide_hal/fake_hal.h"

namespace gg = graspguide;
namespace gd = graspguide::device;
namespace gl = graspguide::link;
namespace gh = graspguide::hal;

// A macro, so every invariant traps at its own address and libFuzzer tells them apart.
#define REQUIRE(cond, what)                                                                 \
  do {                                                                                      \
    if (!(cond)) {                                                                          \
      std::fprintf(stderr, "fuzz_device: invariant violated: %s (%s:%d)\n", what, __FILE__, \
                   __LINE__);                                                               \
      __builtin_trap();                                                                     \
    }                                                                                       \
  } while (0)

namespace {

constexpr uint32_t kStaleUs = gd::kDefaultStaleTimeoutUs;
constexpr uint64_t kTrialGraceUs = 1000000;  // invariant 4's margin past timeout_s
constexpr uint32_t kImuStaleUs = uint32_t(GRASPGUIDE_IMU_STALE_MS) * 1000u;
// The simulated device's IMU ranges (src/boards/posix_sim/main.cpp).
constexpr float kG = 9.80665f;
constexpr float kAccelFs = 8.0f * kG;
constexpr float kGyroFs = 2000.0f * 3.14159265f / 180.0f;
// The plan region and room for 12 records: small, so a full log is reached too.
constexpr uint32_t kStoreBytes = gd::kPlanRegionBytes + 12 * gd::kLogSlotBytes;
// Trials one plan-upload operation sends at most (a plan may say it has more).
constexpr uint16_t kUploadTrialsMax = 8;

// ---- reading the input ---------------------------------------------------------------------

// Bytes in order; past the end every read is 0, so any input is a whole program.
class Input {
 public:
  Input(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  bool done() const { return at_ >= size_; }
  uint8_t u8() { return at_ < size_ ? data_[at_++] : 0; }
  uint16_t u16() {
    const uint16_t lo = u8();
    return uint16_t(lo | u8() << 8);
  }
  uint32_t u32() {
    const uint32_t lo = u16();
    return lo | uint32_t(u16()) << 16;
  }
  float f32() {
    const uint32_t bits = u32();
    float f;
    std::memcpy(&f, &bits, sizeof f);
    return f;
  }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t at_ = 0;
};

// Values at the edges of what the device checks, and past them.
float special_float(unsigned i) {
  static const float kValues[32] = {NAN,
                                    -NAN,
                                    INFINITY,
                                    -INFINITY,
                                    0.0f,
                                    -0.0f,
                                    FLT_MAX,
                                    -FLT_MAX,
                                    FLT_MIN,
                                    std::numeric_limits<float>::denorm_min(),
                                    1e30f,
                                    -1e30f,
                                    9.3e12f,        // the int64-overflow timeout
                                    9.2233720e12f,  // INT64_MAX us in s
                                    float(gg::kTrialTimeoutMaxS),
                                    std::nextafter(float(gg::kTrialTimeoutMaxS), INFINITY),
                                    float(gg::kTrialHoldMaxS),
                                    std::nextafter(float(gg::kTrialHoldMaxS), INFINITY),
                                    float(gg::kTrialThresholdMaxDeg),
                                    std::nextafter(float(gg::kTrialThresholdMaxDeg), INFINITY),
                                    2147.483648f,
                                    4294.967296f,  // 2^31 and 2^32 us in s
                                    1e-30f,
                                    0.5f,
                                    90.0f,
                                    1.0f,
                                    -1.0f,
                                    1e-7f,
                                    1e7f,
                                    1e-3f,
                                    16777216.0f,
                                    -1e-3f};
  return kValues[i % 32];
}

// A field value: the template's, moved a little or a lot, or anything at all.
float value(Input& in, float dflt) {
  const uint8_t b = in.u8();
  const int small = b >> 3;  // 0..31
  switch (b & 7) {
    case 0:
      return special_float(unsigned(small));
    case 1:
      return dflt * (1.0f + float(small - 16) / 64.0f);
    case 2:
      return dflt + float(small - 16) * 1e-3f;  // up to 16 mm for a contact
    case 3:
      return in.f32();  // any bit pattern
    case 4:
      return float(int8_t(in.u8())) * std::pow(10.0f, float(small % 8) - 4.0f);
    case 5:
      return -dflt;
    case 6:
      return std::ldexp(dflt, small - 16);
    default:
      return dflt + float(small) * 1e-6f;  // nearly the same: near-degenerate
  }
}

// ---- the host's side of the line -------------------------------------------------------------

struct Event {
  gl::ParseEvent event = gl::ParseEvent::kNone;
  gl::FrameHeader header;
  uint8_t payload[gl::kMaxPayloadSize] = {};
  size_t payload_size = 0;
};

// What the host sent, handed to the device up to one frame delimiter per poll(). A copy of
// the device's parser sees the same bytes, so the harness knows which request each poll
// handled.
class HostLine final : public gh::ByteStream {
 public:
  void send(const uint8_t* data, size_t n) { pending_.insert(pending_.end(), data, data + n); }
  bool has_pending() const { return at_ < pending_.size(); }
  void open_gate() { gate_open_ = true; }

  size_t read(uint8_t* buffer, size_t capacity) override {
    size_t n = 0;
    while (gate_open_ && n < capacity && at_ < pending_.size()) {
      const uint8_t b = pending_[at_++];
      buffer[n++] = b;
      const gl::ParseEvent e = mirror_.push(b);
      if (e != gl::ParseEvent::kNone) {
        Event& ev = events_.emplace_back();
        ev.event = e;
        if (gl::has_trusted_header(e)) {
          const gl::FrameView& f = mirror_.frame();
          ev.header = f.header;
          ev.payload_size = f.payload_size;
          std::memcpy(ev.payload, f.payload, f.payload_size);
        }
      }
      if (b == gl::kFrameDelimiter) gate_open_ = false;
    }
    if (at_ == pending_.size()) {
      pending_.clear();
      at_ = 0;
    }
    return n;
  }

  size_t write(const uint8_t* data, size_t length) override {
    written_.insert(written_.end(), data, data + length);
    return length;
  }

  // Per poll: the parse events the device saw and the bytes it wrote.
  std::vector<Event> events_;
  std::vector<uint8_t> written_;
  gl::FrameParser mirror_{gl::Accept::kHostToDevice};

 private:
  std::vector<uint8_t> pending_;
  size_t at_ = 0;
  bool gate_open_ = false;
};

// The simulated device's --virtual-clock: device time is the POSE's host time.
class VirtualTime final : public gd::PoseTimeListener {
 public:
  explicit VirtualTime(gh::FakeClock& clock) : clock_(clock) {}
  void on_pose_time(uint32_t t) override { clock_.set_us(t); }

 private:
  gh::FakeClock& clock_;
};

struct DeviceFrame {
  uint8_t id = 0;
  uint8_t payload[gl::kMaxPayloadSize] = {};
  size_t size = 0;
  template <class Msg>
  Msg as() const {
    Msg m;
    REQUIRE(gl::unpack(payload, size, &m) == gl::LinkStatus::kOk, "a device frame decodes");
    return m;
  }
};

// TRIAL_RESULT and HOSTLESS_EVENT come unasked; every other frame answers a request.
bool is_answer(uint8_t id) {
  return id != uint8_t(gl::MsgId::kTrialResult) && id != uint8_t(gl::MsgId::kHostlessEvent);
}

// The device's store: RAM with its faults (fake_storage.h), and invariant 6's first rule
// checked at every write.
class WatchedStore final : public gd::NvStorage {
 public:
  explicit WatchedStore(const gh::RecordingMotors& motors) : motors_(motors) {}
  uint32_t size_bytes() const override { return ram_.size_bytes(); }
  bool read(uint32_t offset, uint8_t* out, uint32_t n) override {
    return ram_.read(offset, out, n);
  }
  bool write(uint32_t offset, const uint8_t* data, uint32_t n) override {
    REQUIRE(motors_.all_off(), "no store write happens with a motor on (it blocks the loop)");
    return ram_.write(offset, data, n);
  }
  gd::RamStorage<kStoreBytes>& ram() { return ram_; }

 private:
  gd::RamStorage<kStoreBytes> ram_;
  const gh::RecordingMotors& motors_;
};

// What a power cycle rebuilds: the application, the runner (boot() mounts the store) and
// the link.
struct Board {
  Board(gh::ByteStream& line, gh::RecordingMotors& motors, gh::FakeClock& clock,
        gd::NvStorage& store, const gd::DeviceInfo& info, gd::PoseTimeListener* time, bool hostless)
      : app(motors, clock),
        runner(motors, clock, store, gh::ImuOutput::kSixAxis, kAccelFs, kGyroFs),
        boot(runner.boot()),
        device(line, app, info, time, hostless ? &runner : nullptr) {}
  gd::Application app;
  gd::HostlessRunner runner;
  gd::StoreStatus boot;
  gd::LinkDevice device;
};

// ---- operations ---------------------------------------------------------------------------------

enum class Op : uint8_t {
  kHello,
  kSetScene,
  kStartTrial,
  kPose,
  kStop,
  kSetMotors,
  kGetStatus,
  kAdvance,
  kRawFrame,
  kGarbage,
  kPlanBegin,
  kPlanTrial,
  kPlanCommit,
  kPlanUpload,
  kHostlessRun,
  kLogInfo,
  kLogRead,
  kLogErase,
  kSimSample,
  kSimSamples,
  kSimButton,
  kStore,
};
// An op byte: the low 5 bits pick the operation (POSE is most of a tracker session, IMU
// samples of a host-less one), the high 3 are flags; flag 0x1 sends a delimiter first (what
// a host does to end a partial frame).
constexpr Op kOpOfSlot[32] = {Op::kHello,       Op::kSetScene,  Op::kStartTrial, Op::kPose,
                              Op::kPose,        Op::kPose,      Op::kPose,       Op::kStop,
                              Op::kSetMotors,   Op::kGetStatus, Op::kAdvance,    Op::kAdvance,
                              Op::kRawFrame,    Op::kGarbage,   Op::kSetScene,   Op::kStartTrial,
                              Op::kPlanBegin,   Op::kPlanTrial, Op::kPlanCommit, Op::kPlanUpload,
                              Op::kHostlessRun, Op::kLogInfo,   Op::kLogRead,    Op::kLogErase,
                              Op::kSimSample,   Op::kSimSample, Op::kSimSamples, Op::kSimSamples,
                              Op::kSimButton,   Op::kStore,     Op::kAdvance,    Op::kPose};
constexpr uint8_t kFlagDelimiterFirst = 0x1;

constexpr float kTimeoutsS[4] = {90.0f, 2.0f, 0.25f, 1800.0f};
constexpr float kWrenches[4][6] = {{0.4f, -1.0f, 0.3f, 0, 0, 0},
                                   {0, 0, -2.0f, 0, 0, 0},
                                   {0, -2.0f, 0, 0.01f, 0, 0},
                                   {1.0f, 0.5f, 0, 0, 0, 0.05f}};
constexpr float kPi = 3.14159265f;

gl::SetScene scene_template(uint8_t t) {
  gl::SetScene m;
  m.k = (t & 1) ? 3 : 4;
  const auto c = graspguide_test::nominal_hand();
  for (int i = 0; i < m.k; ++i)
    for (int j = 0; j < 3; ++j) m.contacts[i][j] = float(c(j, i));
  m.constraints = gl::EnumInfo<gl::ConstraintModel>::kValues[(t >> 1) % 3];
  m.policy = gl::EnumInfo<gl::Policy>::kValues[(t >> 3) & 1];
  m.mode = gl::EnumInfo<gl::Mode>::kValues[(t >> 4) & 1];
  m.timeout_s = kTimeoutsS[(t >> 5) & 3];
  m.hold_s = (t & 0x80) ? 0.0f : std::fmin(0.5f, m.timeout_s / 2);
  return m;
}

gl::Pose pose_template(uint8_t t) {
  gl::Pose m;
  // Rotations about x, y, z by 0..180 deg: near, far and opposite the goal orientation.
  static const float kAnglesDeg[8] = {0, 1, 5, 30, 90, 150, 179, 180};
  const float half = kAnglesDeg[t & 7] * kPi / 360.0f;
  const int axis = (t >> 3) % 3;
  m.quat_wxyz[0] = std::cos(half);
  m.quat_wxyz[1 + axis] = std::sin(half);
  if (t & 0x20) {
    m.has_contacts = true;
    const auto c = graspguide_test::nominal_hand();
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 3; ++j) m.contacts[i][j] = float(c(j, i));
  }
  return m;
}

// A host-less plan: 1..4 trials, a rest of 0 to 2 s, the scene templates' timeouts.
gl::PlanBegin plan_begin_template(uint8_t t) {
  gl::PlanBegin m;
  m.participant[0] = 'U';
  m.participant[1] = '1';
  m.simulated = true;
  m.trial_count = uint16_t(1 + (t & 3));
  m.constraints = gl::EnumInfo<gl::ConstraintModel>::kValues[((t >> 2) & 3) % 3];
  static const float kRestS[4] = {0.0f, 0.01f, 0.3f, 2.0f};
  m.rest_s = kRestS[(t >> 4) & 3];
  m.timeout_s = kTimeoutsS[(t >> 6) & 3];
  m.hold_s = std::fmin(0.5f, m.timeout_s / 2);
  const auto c = graspguide_test::nominal_hand();
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) {
      if (i < 3) m.hand_k3[i][j] = float(c(j, i));
      m.hand_k4[i][j] = float(c(j, i));
    }
  return m;
}

gl::PlanTrial plan_trial_template(uint8_t t, uint16_t position) {
  gl::PlanTrial m;
  m.position = position;
  // Flag 0x80: every such trial is trial_index 1 (a plan that repeats one).
  m.trial_index = (t & 0x80) ? 1 : uint16_t(position + 1);
  m.session = 1;
  m.session_trial = uint8_t(position + 1);
  m.k = (t & 1) ? 4 : 3;
  m.policy = gl::EnumInfo<gl::Policy>::kValues[(t >> 1) & 1];
  m.mode = gl::EnumInfo<gl::Mode>::kValues[(t >> 2) & 1];
  std::memcpy(m.wrench, kWrenches[(t >> 3) & 3], sizeof m.wrench);
  m.wrench_number = uint8_t(1 + ((t >> 3) & 3));
  m.familiarization = (t >> 5) & 1;
  return m;
}

// The world's IMU: gravity 0..180 deg from the IMU's -z about x, y or z (a specific force
// pointing up), the hand still or turning.
void sample_template(uint8_t t, gl::SimImuSample& m) {
  static const float kAnglesDeg[8] = {0, 1, 5, 30, 90, 150, 179, 180};
  const float a = kAnglesDeg[t & 7] * kPi / 180.0f;
  const int axis = (t >> 3) % 3;
  float up[3] = {0, 0, std::cos(a)};
  up[axis == 2 ? 0 : (axis == 0 ? 1 : 0)] = std::sin(a);
  for (int i = 0; i < 3; ++i) m.accel_mps2[i] = kG * up[i];
  for (int i = 0; i < 3; ++i) m.gyro_radps[i] = 0;
  if (t & 0x40) m.gyro_radps[axis] = 0.5f;
}

// The next POSE timestamp, and how far the device clock moves before it is sent.
struct PoseTime {
  uint32_t host_us;
  uint32_t clock_step_us;
};

PoseTime pose_time(Input& in, uint32_t prev) {
  const uint8_t b = in.u8();
  const uint32_t small = b >> 3;  // 0..31
  constexpr uint32_t kFrameUs = 10000;
  switch (b & 7) {
    case 0:
    case 1:
    case 2: {  // a tracker at 100 Hz down to ~3 Hz
      const uint32_t dt = kFrameUs * (1 + small);
      return {prev + dt, dt};
    }
    case 3:
      return {prev + in.u32(), kFrameUs};  // any jump, 2^31 and more included
    case 4:
      return {in.u32(), kFrameUs};
    case 5: {
      const uint32_t kEdges[12] = {0u,
                                   0xFFFFFFFFu,
                                   0x7FFFFFFFu,
                                   0x80000000u,
                                   prev + 0x80000000u,
                                   prev + 0x7FFFFFFFu,
                                   prev + 0x80000001u,
                                   prev - 1,
                                   prev,
                                   prev - kFrameUs,
                                   0xFFFFFFFFu - 5000u,
                                   prev + 0xFFFFFFFFu / 3};
      return {kEdges[small % 12], kFrameUs};
    }
    case 6:
      return {prev - small * 1000u, kFrameUs};  // a little back in time
    default:
      return {prev + small * 1000000u, small * 1000000u};  // seconds of tracking loss
  }
}

// The longest gap between two polls: with it, a trial's device-clock time stays below
// 2^31 us (max timeout + slack + this), so a signed 32-bit difference tells it. A board
// polls every few ms; this is a frozen or suspended device, still unambiguous.
constexpr uint32_t kMaxPollGapUs = 340000000u;

uint32_t clock_step(Input& in) {
  const uint8_t b = in.u8();
  const uint32_t small = b >> 3;
  switch (b & 7) {
    case 0:
      return kStaleUs - 1;
    case 1:
      return kStaleUs;
    case 2:
      return kStaleUs + small * 1000u;
    case 3:
      return small * 1000u;
    case 4:
      return small * 1000000u;
    case 5:
      return small * 10000000u;  // up to 310 s
    case 6:
      return in.u32() % (kMaxPollGapUs + 1);
    default:
      return small * 10000u;
  }
}

// ---- the rig
// --------------------------------------------------------------------------------------

class Rig {
 public:
  explicit Rig(uint8_t config)
      : virtual_clock_(config & 1), hostless_(!(config & 4)), virtual_time_(clock_) {
    // Near the u32 wrap, so trials and the watchdog cross it.
    if (config & 2) clock_.set_us(0xFFFFFFFFu - 1000000u);
    // The simulated device's capabilities: with the runner, the host-less and sim messages.
    if (hostless_)
      info_.capabilities =
          uint8_t(info_.capabilities | gl::kCapabilityHostless | gl::kCapabilitySimMessages);
    boot();
  }

  void run(Input& in) {
    while (!in.done()) {
      const uint8_t b = in.u8();
      const Op op = kOpOfSlot[b & 31];
      const uint8_t flags = b >> 5;
      const bool delimiter = flags & kFlagDelimiterFirst;
      switch (op) {
        case Op::kHello: {
          gl::Hello m;
          if (flags & 2) m.protocol_version = in.u8();
          send(m, delimiter);
          break;
        }
        case Op::kSetScene:
          send(scene(in), delimiter);
          break;
        case Op::kStartTrial:
          send(start_trial(in), delimiter);
          break;
        case Op::kPose: {
          gl::Pose m = pose_template(in.u8());
          const PoseTime t = pose_time(in, last_host_us_);
          m.host_time_us = last_host_us_ = t.host_us;
          override_pose(in, m);
          advance(t.clock_step_us);
          send(m, delimiter);
          break;
        }
        case Op::kStop:
          send(gl::Stop{}, delimiter);
          break;
        case Op::kSetMotors: {
          gl::SetMotors m;
          for (uint8_t& d : m.pwm) d = in.u8();
          send(m, delimiter);
          break;
        }
        case Op::kGetStatus:
          send(gl::GetStatus{}, delimiter);
          break;
        case Op::kAdvance:
          advance(clock_step(in));
          break;
        case Op::kRawFrame:
          raw_frame(in, flags, delimiter);
          break;
        case Op::kGarbage: {
          uint8_t bytes[128];
          const size_t n = in.u8() % sizeof bytes;
          for (size_t i = 0; i < n; ++i) bytes[i] = in.u8();
          line_.send(bytes, n);
          deliver();
          break;
        }
        case Op::kPlanBegin:
          send(plan_begin(in), delimiter);
          break;
        case Op::kPlanTrial: {
          const uint16_t position = (flags & 2) ? in.u16() : upload_next_;
          send(plan_trial(in, position), delimiter);
          break;
        }
        case Op::kPlanCommit: {
          gl::PlanCommit m;
          m.trial_count = (flags & 2) ? in.u16() : upload_count_;
          send(m, delimiter);
          break;
        }
        case Op::kPlanUpload: {
          const gl::PlanBegin b = plan_begin(in);
          send(b, delimiter);
          const uint16_t n = b.trial_count < kUploadTrialsMax ? b.trial_count : kUploadTrialsMax;
          for (uint16_t i = 0; i < n; ++i) send(plan_trial(in, i), false);
          gl::PlanCommit m;
          m.trial_count = (flags & 2) ? in.u16() : b.trial_count;
          send(m, false);
          break;
        }
        case Op::kHostlessRun:
          send(gl::HostlessRun{}, delimiter);
          break;
        case Op::kLogInfo:
          send(gl::LogInfoGet{}, delimiter);
          break;
        case Op::kLogRead: {
          gl::LogRead m;
          m.index = (flags & 2) ? in.u16() : uint16_t(in.u8() % 16);
          send(m, delimiter);
          break;
        }
        case Op::kLogErase: {
          gl::LogErase m;
          m.key = (flags & 2) ? in.u32() : gl::kLogEraseKey;
          send(m, delimiter);
          break;
        }
        case Op::kSimSample:
          sim_sample(in, in.u8(), delimiter);
          break;
        case Op::kSimSamples:
          sim_samples(in, flags);
          break;
        case Op::kSimButton: {
          gl::SimButton m;
          m.pressed = in.u8() & 1;
          send(m, delimiter);
          break;
        }
        case Op::kStore:
          hurt_store(in);
          break;
      }
    }
  }

 private:
  // ---- building requests
  gl::SetScene scene(Input& in) {
    gl::SetScene m = scene_template(in.u8());
    for (int n = in.u8() % 8; n > 0; --n) {
      const uint8_t f = in.u8() % 19;
      if (f < 12)
        m.contacts[f / 3][f % 3] = value(in, m.contacts[f / 3][f % 3]);
      else if (f < 15)
        m.y_axis[f - 12] = value(in, m.y_axis[f - 12]);
      else if (f == 15)
        m.threshold_deg = value(in, m.threshold_deg);
      else if (f == 16)
        m.hold_s = value(in, m.hold_s);
      else if (f == 17)
        m.timeout_s = value(in, m.timeout_s);
      else
        m.k = in.u8();
    }
    return m;
  }

  gl::StartTrial start_trial(Input& in) {
    gl::StartTrial m;
    m.trial_id = ++trial_ids_;
    const uint8_t t = in.u8();
    std::memcpy(m.wrench, kWrenches[t & 3], sizeof m.wrench);
    for (int n = in.u8() % 4; n > 0; --n) {
      const uint8_t f = in.u8() % 6;
      m.wrench[f] = value(in, m.wrench[f]);
    }
    return m;
  }

  gl::PlanBegin plan_begin(Input& in) {
    gl::PlanBegin m = plan_begin_template(in.u8());
    for (int n = in.u8() % 6; n > 0; --n) {
      const uint8_t f = in.u8() % 42;
      if (f < 3)
        m.y_axis[f] = value(in, m.y_axis[f]);
      else if (f == 3)
        m.threshold_deg = value(in, m.threshold_deg);
      else if (f == 4)
        m.hold_s = value(in, m.hold_s);
      else if (f == 5)
        m.timeout_s = value(in, m.timeout_s);
      else if (f == 6)
        m.rest_s = value(in, m.rest_s);
      else if (f < 16)
        m.hand_k3[(f - 7) / 3][(f - 7) % 3] = value(in, m.hand_k3[(f - 7) / 3][(f - 7) % 3]);
      else if (f < 28)
        m.hand_k4[(f - 16) / 3][(f - 16) % 3] = value(in, m.hand_k4[(f - 16) / 3][(f - 16) % 3]);
      else if (f < 32)
        m.imu_to_hand_wxyz[f - 28] = value(in, m.imu_to_hand_wxyz[f - 28]);
      else if (f < 36)
        m.gain[f - 32] = value(in, m.gain[f - 32]);
      else if (f == 36)
        m.trial_count = in.u16();
      else if (f < 41)
        m.pwm_floor[f - 37] = in.u8();
      else  // any printable id of 0..8 characters (anything else does not encode: raw frames)
        for (size_t i = 0, n = in.u8() % (sizeof m.participant + 1); i < sizeof m.participant; ++i)
          m.participant[i] = i < n ? char(0x20 + in.u8() % 95) : '\0';
    }
    upload_next_ = 0;
    upload_count_ = m.trial_count;
    return m;
  }

  gl::PlanTrial plan_trial(Input& in, uint16_t position) {
    gl::PlanTrial m = plan_trial_template(in.u8(), position);
    for (int n = in.u8() % 4; n > 0; --n) {
      const uint8_t f = in.u8() % 10;
      if (f < 6)
        m.wrench[f] = value(in, m.wrench[f]);
      else if (f == 6)
        m.k = in.u8();
      else if (f == 7)
        m.trial_index = in.u16();
      else if (f == 8)
        m.session = in.u8();
      else
        m.wrench_number = in.u8();
    }
    upload_next_ = uint16_t(position + 1);
    return m;
  }

  // One sample of the world, timed as a POSE is (any step, jump or step back).
  void sim_sample(Input& in, uint8_t t, bool delimiter) {
    gl::SimImuSample m;
    sample_template(t, m);
    for (int n = in.u8() % 3; n > 0; --n) {
      const uint8_t f = in.u8() % 6;
      float& v = f < 3 ? m.accel_mps2[f] : m.gyro_radps[f - 3];
      v = value(in, v);
    }
    const PoseTime pt = pose_time(in, last_sample_host_us_);
    send_sample(m, pt, delimiter);
  }

  // A steady 100 Hz stream of one template (a held hand), up to 64 samples. Flag 0x2 holds
  // the hand aligned with the running trial's force (so trials succeed); flag 0x4 presses
  // the button whenever the device waits for it (a wearer who is ready).
  void sim_samples(Input& in, uint8_t flags) {
    const uint8_t t = in.u8();
    const int n = 1 + in.u8() % 64;
    gl::SimImuSample m;
    sample_template(t, m);
    for (int i = 0; i < n; ++i) {
      if (flags & 2) aligned(m);
      const float dither = (++dither_ % 2) ? 0.002f : -0.002f;
      gl::SimImuSample d = m;
      for (int j = 0; j < 3; ++j) {
        d.accel_mps2[j] += dither;
        d.gyro_radps[j] += dither;
      }
      send_sample(d, PoseTime{last_sample_host_us_ + 10000u, 10000u}, false);
      if ((flags & 4) && hostless_ && board_->runner.phase() == gd::RunPhase::kWaitButton) {
        gl::SimButton press;
        press.pressed = true;
        send(press, false);
        press.pressed = false;
        send(press, false);
      }
    }
  }

  void send_sample(gl::SimImuSample& m, const PoseTime& t, bool delimiter) {
    m.time_us = last_sample_host_us_ = t.host_us;
    advance(t.clock_step_us);
    send(m, delimiter);
  }

  // The specific force of a hand whose gravity lies along the running trial's force (the
  // plan's mounting taken as the identity): its guidance error is near zero.
  void aligned(gl::SimImuSample& m) {
    if (!hostless_ || !board_->runner.running()) return;
    const gd::StudyPlan& plan = board_->runner.plan();
    const uint16_t p = board_->runner.position();
    if (p >= plan.header.trial_count || p >= gd::kMaxPlanTrials) return;
    const gd::PlanTrial& t = plan.trials[p];
    if (t.k != 3 && t.k != 4) return;
    gg::Scene<gg::Real> scene;
    scene.k = t.k;
    scene.contacts.setZero();
    for (int i = 0; i < t.k; ++i)
      for (int j = 0; j < 3; ++j)
        scene.contacts(j, i) = t.k == 3 ? plan.header.hand_k3[i][j] : plan.header.hand_k4[i][j];
    gg::Guidance<gg::Real> g;
    gg::Vec6<gg::Real> w;
    for (int j = 0; j < 6; ++j) w(j) = t.wrench[j];
    gg::FrameResult<gg::Real> f;
    if (g.set_scene(scene) != gg::Status::kOk || g.set_wrench(w) != gg::Status::kOk ||
        g.update(Eigen::Matrix<gg::Real, 4, 1>(1, 0, 0, 0), f) != gg::Status::kOk)
      return;
    for (int i = 0; i < 3; ++i) m.accel_mps2[i] = -kG * float(g.grasp().force_unit(i));
  }

  // The store's faults (fake_storage.h), a flipped bit, or a power cycle.
  void hurt_store(Input& in) {
    gd::RamStorage<kStoreBytes>& ram = store_.ram();
    switch (in.u8() % 6) {
      case 0:
        ram.fail_writes_after_bytes(in.u16() % 2048);
        break;
      case 1:
        ram.fail_reads(true);
        break;
      case 2:
        ram.fail_reads(false);
        break;
      case 3:
        ram.restore_power();
        break;
      case 4:
        boot();
        break;
      default: {
        const uint32_t at = (uint32_t(in.u16()) * 7u) % kStoreBytes;
        ram.bytes()[at] = uint8_t(ram.bytes()[at] ^ (1u << (in.u8() & 7)));
        break;
      }
    }
  }

  // Power up (again): a new application, runner and link on the same store and clock.
  void boot() {
    board_.reset();
    board_ = std::make_unique<Board>(line_, motors_, clock_, store_, info_,
                                     virtual_clock_ ? &virtual_time_ : nullptr, hostless_);
    line_.mirror_ = gl::FrameParser{gl::Accept::kHostToDevice};
    first_pose_seen_ = false;
    REQUIRE(motors_.all_off(), "the motors are off after a reboot, whatever the store holds");
  }

  gd::Application& app() { return board_->app; }
  gd::LinkDevice& dev() { return board_->device; }
  bool run_going() { return hostless_ && board_->runner.running(); }

  void override_pose(Input& in, gl::Pose& m) {
    for (int n = in.u8() % 4; n > 0; --n) {
      const uint8_t f = in.u8() % 16;
      float& v = f < 4 ? m.quat_wxyz[f] : m.contacts[(f - 4) / 3][(f - 4) % 3];
      v = value(in, v);
    }
  }

  // Any header and payload with the right CRC: a bad version, an unknown or device -> host
  // id, a wrong length, or (flag 0x2) a valid request with one byte changed, e.g. a bad enum.
  void raw_frame(Input& in, uint8_t flags, bool delimiter) {
    gl::FrameHeader h;
    h.version = (flags & 4) ? in.u8() : gl::kProtocolVersion;
    h.msg_id = in.u8();
    h.seq = seq_.next();
    uint8_t payload[gl::kMaxPayloadSize] = {};
    size_t size = 0;
    if (flags & 2) {
      switch (h.msg_id % 4) {
        case 0:
          h.msg_id = uint8_t(gl::MsgId::kSetScene);
          gl::pack(scene_template(in.u8()), payload, sizeof payload, &size);
          break;
        case 1:
          h.msg_id = uint8_t(gl::MsgId::kPose);
          gl::pack(pose_template(in.u8()), payload, sizeof payload, &size);
          break;
        case 2:
          h.msg_id = uint8_t(gl::MsgId::kStartTrial);
          gl::pack(gl::StartTrial{}, payload, sizeof payload, &size);
          break;
        default:
          h.msg_id = uint8_t(gl::MsgId::kHello);
          gl::pack(gl::Hello{}, payload, sizeof payload, &size);
          break;
      }
      const uint8_t at = in.u8();
      payload[at % size] = in.u8();
    } else {
      size = in.u8() % (gl::kMaxPayloadSize + 1);
      for (size_t i = 0; i < size; ++i) payload[i] = in.u8();
    }
    uint8_t wire[gl::kMaxWireFrameSize + 1];
    size_t n = 0;
    wire[0] = gl::kFrameDelimiter;
    const size_t at = delimiter ? 1 : 0;
    REQUIRE(
        gl::encode_frame(h, payload, size, wire + at, sizeof wire - at, &n) == gl::LinkStatus::kOk,
        "harness: encode_frame takes any header and payload");
    line_.send(wire, at + n);
    deliver();
  }

  template <class Msg>
  void send(const Msg& m, bool delimiter_first) {
    uint8_t wire[gl::kMaxWireFrameSize + 1];
    size_t n = 0;
    wire[0] = gl::kFrameDelimiter;
    const size_t at = delimiter_first ? 1 : 0;
    REQUIRE(gl::write_frame(m, seq_.next(), wire + at, sizeof wire - at, &n) == gl::LinkStatus::kOk,
            "harness: write_frame takes every request it builds");
    line_.send(wire, at + n);
    deliver();
  }

  void deliver() {
    while (line_.has_pending()) {
      line_.open_gate();
      poll();
    }
  }

  void advance(uint32_t dt) {
    clock_.advance_us(dt);
    clock64_ += dt;
    silence_us_ += dt;
    sample_silence_us_ += dt;
    poll();
  }

  // ---- one poll and every invariant on what it did
  void poll() {
    const gd::DeviceState before = app().state();
    const bool motors_on_before = app().motors_on();
    const bool run_before = run_going();
    line_.events_.clear();
    line_.written_.clear();
    dev().poll();
    const gd::DeviceState after = app().state();
    const bool run_after = run_going();
    // The device drops a partial frame after a silence; the mirror follows it.
    if (line_.mirror_.mid_frame() && !dev().parser().mid_frame()) line_.mirror_.discard_partial();
    REQUIRE(dev().parser().good_frames() == line_.mirror_.good_frames() &&
                dev().parser().bad_frames() == line_.mirror_.bad_frames(),
            "harness: the mirror parser saw what the device's parser saw");

    std::vector<DeviceFrame> out;
    for (uint8_t b : line_.written_) {
      const gl::ParseEvent e = host_.push(b);
      REQUIRE(e == gl::ParseEvent::kNone || e == gl::ParseEvent::kFrame,
              "every frame the device writes parses on the host");
      if (e != gl::ParseEvent::kFrame) continue;
      const gl::FrameView& f = host_.frame();
      DeviceFrame& d = out.emplace_back();
      d.id = f.header.msg_id;
      d.size = f.payload_size;
      std::memcpy(d.payload, f.payload, f.payload_size);
      REQUIRE(gl::visit_payload(d.id, d.payload, d.size, [](const auto&) {}) == gl::LinkStatus::kOk,
              "every frame the device writes decodes");
    }
    REQUIRE(line_.written_.empty() || line_.written_.back() == gl::kFrameDelimiter,
            "the device writes whole frames");

    // The request this poll handled, if its header can be trusted.
    const Event* req = nullptr;
    bool dropped = false;
    for (const Event& e : line_.events_) {
      if (e.event != gl::ParseEvent::kFrame) dropped = true;
      if (gl::has_trusted_header(e.event)) {
        REQUIRE(req == nullptr, "harness: one frame per poll");
        req = &e;
      }
    }
    gl::LinkStatus decoded = gl::LinkStatus::kOk;
    if (req && req->event == gl::ParseEvent::kFrame)
      decoded = gl::visit_payload(req->header.msg_id, req->payload, req->payload_size,
                                  [](const auto&) {});
    const bool good_request =
        req && req->event == gl::ParseEvent::kFrame && decoded == gl::LinkStatus::kOk;
    const uint8_t req_id = req ? req->header.msg_id : 0;
    auto is_req = [&](gl::MsgId id) { return good_request && req_id == uint8_t(id); };

    if (trace_) print_poll(req, out, after);

    // 5. One answer per trusted request, of the right kind, with its seq; none otherwise.
    const DeviceFrame* answer = nullptr;
    size_t answers = 0;
    bool error_sent = false, result_sent = false;
    for (const DeviceFrame& d : out) {
      if (d.id == uint8_t(gl::MsgId::kError)) error_sent = true;
      if (d.id == uint8_t(gl::MsgId::kTrialResult)) result_sent = true;
      if (is_answer(d.id)) {
        answer = &d;
        ++answers;
      }
    }
    REQUIRE(answers == (req ? 1u : 0u),
            "each trusted request gets exactly one answer, nothing else does");
    if (answer) {
      const uint8_t a = answer->id;
      if (a == uint8_t(gl::MsgId::kAck))
        REQUIRE(answer->as<gl::Ack>().request_seq == req->header.seq,
                "ACK echoes the request's seq");
      if (a == uint8_t(gl::MsgId::kError))
        REQUIRE(answer->as<gl::Error>().request_seq == req->header.seq,
                "ERROR echoes the request's seq");
      if (a == uint8_t(gl::MsgId::kHelloReply))
        REQUIRE(answer->as<gl::HelloReply>().request_seq == req->header.seq,
                "HELLO_REPLY echoes the seq");
      gl::ErrorCode code;
      if (req->event != gl::ParseEvent::kFrame) {
        REQUIRE(gl::error_code_for(req->event, &code) && a == uint8_t(gl::MsgId::kError) &&
                    answer->as<gl::Error>().code == code,
                "a bad frame with a trusted header is answered with its ERROR");
      } else if (!good_request) {
        REQUIRE(a == uint8_t(gl::MsgId::kError) &&
                    answer->as<gl::Error>().code == gl::ErrorCode::kBadEnumValue,
                "a payload that does not decode is answered with ERROR bad_enum_value");
      } else {
        const bool is_ack_or_error =
            a == uint8_t(gl::MsgId::kAck) || a == uint8_t(gl::MsgId::kError);
        switch (gl::MsgId(req_id)) {
          case gl::MsgId::kHello:
            REQUIRE(a == uint8_t(gl::MsgId::kHelloReply), "HELLO -> HELLO_REPLY");
            break;
          case gl::MsgId::kGetStatus:
            REQUIRE(a == uint8_t(gl::MsgId::kStatus), "GET_STATUS -> STATUS");
            break;
          case gl::MsgId::kStop:
            REQUIRE(a == uint8_t(gl::MsgId::kAck), "STOP -> ACK");
            break;
          case gl::MsgId::kPose:
            REQUIRE(a == uint8_t(gl::MsgId::kTelemetry) || a == uint8_t(gl::MsgId::kError),
                    "POSE -> TELEMETRY or ERROR");
            break;
          case gl::MsgId::kSimImuSample:
            REQUIRE(a == uint8_t(gl::MsgId::kTelemetry) || is_ack_or_error,
                    "SIM_IMU_SAMPLE -> TELEMETRY, ACK or ERROR");
            REQUIRE(a != uint8_t(gl::MsgId::kTelemetry) || run_before,
                    "SIM_IMU_SAMPLE is answered with TELEMETRY only during a host-less run");
            break;
          case gl::MsgId::kLogInfoGet:
            REQUIRE(a == uint8_t(gl::MsgId::kLogInfo) || a == uint8_t(gl::MsgId::kError),
                    "LOG_INFO_GET -> LOG_INFO or ERROR");
            REQUIRE((a == uint8_t(gl::MsgId::kLogInfo)) == hostless_,
                    "LOG_INFO_GET is answered by a board with a host-less runner only");
            break;
          case gl::MsgId::kLogRead:
            REQUIRE(a == uint8_t(gl::MsgId::kLogRecord) || a == uint8_t(gl::MsgId::kError),
                    "LOG_READ -> LOG_RECORD or ERROR");
            break;
          default:
            REQUIRE(is_ack_or_error, "every other request -> ACK or ERROR");
            break;
        }
      }
    }
    const bool acked = answer && answer->id == uint8_t(gl::MsgId::kAck);

    // 2. Every ERROR turns the motors off; STOP too. 6. An ERROR or a dropped frame ends a
    // host-less run, or its next pattern pulse would turn them on again.
    REQUIRE(!error_sent || motors_.all_off(), "every ERROR leaves the motors off");
    REQUIRE(!dropped || motors_.all_off(), "every dropped frame leaves the motors off");
    REQUIRE(!(error_sent || dropped) || !run_after, "an ERROR or a dropped frame ends a run");
    if (is_req(gl::MsgId::kStop)) {
      REQUIRE(motors_.all_off(), "STOP leaves the motors off");
      REQUIRE(after != gd::DeviceState::kTrialRunning, "STOP ends a running trial");
    }

    // 5. TELEMETRY tells what the motors got.
    for (const DeviceFrame& d : out) {
      if (d.id != uint8_t(gl::MsgId::kTelemetry)) continue;
      const gl::Telemetry t = d.as<gl::Telemetry>();
      REQUIRE(std::memcmp(t.pwm, motors_.last().duty, sizeof t.pwm) == 0,
              "TELEMETRY.pwm is what the motors got");
      const bool flag = t.flags & gl::kTelemetryFlagTrialRunning;
      // A host-less pattern plays whatever the IMU says; guidance never runs on a failure.
      REQUIRE(t.solver_status == gl::ErrorCode::kOk || motors_.all_off() ||
                  (is_req(gl::MsgId::kSimImuSample) && !flag),
              "a TELEMETRY with a solver failure means the motors are off");
      if (is_req(gl::MsgId::kSimImuSample)) {
        gl::SimImuSample m;
        gl::unpack(req->payload, req->payload_size, &m);
        REQUIRE(t.host_time_us == m.time_us, "TELEMETRY echoes the sample's time_us");
        REQUIRE(flag == (hostless_ && board_->runner.phase() == gd::RunPhase::kTrial),
                "a sample's TELEMETRY flag says whether a host-less trial runs");
        continue;
      }
      gl::Pose p;
      gl::unpack(req->payload, req->payload_size, &p);
      REQUIRE(t.host_time_us == p.host_time_us, "TELEMETRY echoes the POSE's host_time_us");
      // The host ends its trial loop on a clear flag (tools/graspguide/study/runner.py).
      REQUIRE(flag == (after == gd::DeviceState::kTrialRunning),
              "TELEMETRY's trial_running flag says whether the trial still runs");
    }
    if (is_req(gl::MsgId::kGetStatus)) {
      const gl::Status s = answer->as<gl::Status>();
      REQUIRE(uint8_t(s.state) == uint8_t(app().state()), "STATUS.state is the device's state");
      REQUIRE(s.frames_received == line_.mirror_.good_frames() &&
                  s.bad_frames == line_.mirror_.bad_frames(),
              "STATUS counts the frames the device parsed");
    }

    // 3. The watchdog: a device clock silent for the watchdog's time leaves the motors off
    // (a host-less run drives them with no POSE: invariant 6 watches it).
    if (is_req(gl::MsgId::kPose) || is_req(gl::MsgId::kSetMotors)) silence_us_ = 0;
    REQUIRE(silence_us_ < kStaleUs || run_after || motors_.all_off(),
            "no POSE or SET_MOTORS for the watchdog's time: the motors are off after poll()");

    // 6. The host-less runner and its store.
    if (is_req(gl::MsgId::kSimImuSample)) sample_silence_us_ = 0;
    if (!virtual_clock_ && run_after && board_->runner.phase() == gd::RunPhase::kTrial &&
        sample_silence_us_ >= kImuStaleUs)
      REQUIRE(motors_.all_off(),
              "a host-less trial without a sample for the IMU's stale time "
              "has its motors off");
    const bool storage_req = is_req(gl::MsgId::kPlanBegin) || is_req(gl::MsgId::kPlanTrial) ||
                             is_req(gl::MsgId::kPlanCommit) || is_req(gl::MsgId::kLogErase);
    if (storage_req && acked)
      REQUIRE(before != gd::DeviceState::kTrialRunning && !motors_on_before && !run_before,
              "PLAN_* and LOG_ERASE are taken only with no trial, no motor on and no run");
    if (is_req(gl::MsgId::kPlanCommit) && acked)
      REQUIRE(board_->runner.plan_stored(), "an acknowledged PLAN_COMMIT leaves a stored plan");
    if (is_req(gl::MsgId::kLogErase) && acked)
      REQUIRE(board_->runner.log().records() == 0 && board_->runner.log().torn() == 0,
              "an acknowledged LOG_ERASE leaves an empty log");
    if (is_req(gl::MsgId::kHostlessRun) && acked)
      REQUIRE(before != gd::DeviceState::kTrialRunning, "HOSTLESS_RUN is refused in a trial");
    if (answer && answer->id == uint8_t(gl::MsgId::kLogInfo)) {
      const gl::LogInfo li = answer->as<gl::LogInfo>();
      gd::ResultsLog& log = board_->runner.log();
      REQUIRE(li.running == run_after && li.plan_stored == board_->runner.plan_stored(),
              "LOG_INFO tells whether a plan is stored and a run goes on");
      REQUIRE(li.records == log.records() && li.capacity == log.capacity() &&
                  li.torn_records == log.torn() && li.records <= li.capacity,
              "LOG_INFO counts the log's records");
    }
    if (answer && answer->id == uint8_t(gl::MsgId::kLogRecord)) {
      const gl::LogRecord r = answer->as<gl::LogRecord>();
      gl::LogRead q;
      gl::unpack(req->payload, req->payload_size, &q);
      REQUIRE(r.index == q.index && r.index < board_->runner.log().records(),
              "LOG_RECORD answers the index asked for, one that is stored");
      REQUIRE((r.k == 3 || r.k == 4) && r.completion_s >= 0 && std::isfinite(r.completion_s),
              "a LOG_RECORD holds what a finished trial stored");
    }

    // Scene and trial bookkeeping, for invariant 4 and TRIAL_RESULT.
    if (is_req(gl::MsgId::kSetScene) && acked) {
      gl::SetScene m;
      gl::unpack(req->payload, req->payload_size, &m);
      gg::TrialConfig c;
      c.threshold_deg = m.threshold_deg;
      c.hold_s = m.hold_s;
      c.timeout_s = m.timeout_s;
      REQUIRE(gg::validate_trial_config(c) == gg::Status::kOk,
              "an accepted SET_SCENE has every trial field within its documented range");
      scene_timeout_s_ = m.timeout_s;
    }
    if (is_req(gl::MsgId::kStartTrial) && acked) {
      REQUIRE(before != gd::DeviceState::kTrialRunning && after == gd::DeviceState::kTrialRunning,
              "an acknowledged START_TRIAL starts a trial");
      gl::StartTrial m;
      gl::unpack(req->payload, req->payload_size, &m);
      trial_id_ = m.trial_id;
      trial_timeout_s_ = scene_timeout_s_;
      first_pose_seen_ = false;
    }
    if (before == gd::DeviceState::kTrialRunning && is_req(gl::MsgId::kPose) && !first_pose_seen_) {
      first_pose_seen_ = true;
      first_pose_us_ = clock64_;
    }
    for (const DeviceFrame& d : out) {
      if (d.id != uint8_t(gl::MsgId::kTrialResult)) continue;
      const gl::TrialResult r = d.as<gl::TrialResult>();
      if (run_before) {  // a host-less trial's, with the plan's timeout
        const double timeout_s = board_->runner.plan().header.timeout_s;
        REQUIRE(r.completion_s >= 0 && r.completion_s <= timeout_s * (1 + 1e-6) + 1e-6,
                "a host-less TRIAL_RESULT.completion_s is within [0, the plan's timeout_s]");
        continue;
      }
      REQUIRE(before == gd::DeviceState::kTrialRunning && r.trial_id == trial_id_,
              "TRIAL_RESULT names the trial that was running");
      REQUIRE(after != gd::DeviceState::kTrialRunning, "TRIAL_RESULT ends the trial");
      // The trial counts whole microseconds: timeout_s rounds to the nearest one.
      REQUIRE(r.completion_s >= 0 && r.completion_s <= double(trial_timeout_s_) * (1 + 1e-6) + 1e-6,
              "TRIAL_RESULT.completion_s is within [0, timeout_s]");
      REQUIRE(r.first_entry_s == -1.0f || (r.first_entry_s >= 0 && std::isfinite(r.first_entry_s)),
              "TRIAL_RESULT.first_entry_s is -1 or a time");
    }
    if (before == gd::DeviceState::kTrialRunning && after != gd::DeviceState::kTrialRunning)
      REQUIRE(result_sent || error_sent || is_req(gl::MsgId::kStop),
              "a trial ends with TRIAL_RESULT, ERROR or STOP");

    // 4. A trial always ends: at most timeout_s + 1 s of device time after its first POSE.
    if (!virtual_clock_ && after == gd::DeviceState::kTrialRunning && first_pose_seen_)
      REQUIRE(clock64_ - first_pose_us_ <= uint64_t(double(trial_timeout_s_) * 1e6) + kTrialGraceUs,
              "a running trial ends once the device clock is timeout_s + 1 s past its first POSE");
  }

  // GRASPGUIDE_FUZZ_TRACE=1: one line per poll, to read what a reproducer does.
  void print_poll(const Event* req, const std::vector<DeviceFrame>& out, gd::DeviceState after) {
    std::fprintf(stderr, "t=%llu us clock=%u", (unsigned long long)clock64_, clock_.now_us());
    if (req) {
      std::fprintf(stderr, " <- %s",
                   req->event == gl::ParseEvent::kFrame ? gl::message_name(req->header.msg_id)
                                                        : gl::parse_event_name(req->event));
      if (req->header.msg_id == uint8_t(gl::MsgId::kPose) && req->event == gl::ParseEvent::kFrame) {
        gl::Pose p;
        gl::unpack(req->payload, req->payload_size, &p);
        std::fprintf(stderr, "(host_time_us=%u)", p.host_time_us);
      }
      if (req->header.msg_id == uint8_t(gl::MsgId::kSetScene) &&
          req->event == gl::ParseEvent::kFrame) {
        gl::SetScene m;
        if (gl::unpack(req->payload, req->payload_size, &m) == gl::LinkStatus::kOk)
          std::fprintf(stderr, "(k=%u threshold_deg=%g hold_s=%g timeout_s=%g)", m.k,
                       double(m.threshold_deg), double(m.hold_s), double(m.timeout_s));
      }
    }
    for (const DeviceFrame& d : out) {
      std::fprintf(stderr, " -> %s", gl::message_name(d.id));
      if (d.id == uint8_t(gl::MsgId::kError)) {
        const gl::Error e = d.as<gl::Error>();
        std::fprintf(stderr, "(%s, detail %u)", gl::enum_name(e.code), e.detail);
      } else if (d.id == uint8_t(gl::MsgId::kTelemetry)) {
        const gl::Telemetry t = d.as<gl::Telemetry>();
        std::fprintf(stderr, "(%s, err %.2f deg, pwm %u,%u,%u,%u)", gl::enum_name(t.solver_status),
                     double(t.error_deg), t.pwm[0], t.pwm[1], t.pwm[2], t.pwm[3]);
      } else if (d.id == uint8_t(gl::MsgId::kHostlessEvent)) {
        const gl::HostlessEvent e = d.as<gl::HostlessEvent>();
        std::fprintf(stderr, "(%s, position %u)", gl::enum_name(e.event), e.position);
      } else if (d.id == uint8_t(gl::MsgId::kTrialResult)) {
        const gl::TrialResult r = d.as<gl::TrialResult>();
        std::fprintf(stderr, "(id %u, success %d, completion %g s, first entry %g s)", r.trial_id,
                     int(r.success), double(r.completion_s), double(r.first_entry_s));
      }
    }
    const gg::Pwm& m = motors_.last();
    std::fprintf(stderr, " | state %u run phase %u motors %u,%u,%u,%u\n", unsigned(after),
                 hostless_ ? unsigned(board_->runner.phase()) : 0u, m.duty[0], m.duty[1], m.duty[2],
                 m.duty[3]);
  }

  const bool trace_ = std::getenv("GRASPGUIDE_FUZZ_TRACE") != nullptr;
  const bool virtual_clock_;
  const bool hostless_;
  gh::FakeClock clock_;
  gh::RecordingMotors motors_;
  HostLine line_;
  VirtualTime virtual_time_;
  gd::DeviceInfo info_;
  WatchedStore store_{motors_};
  std::unique_ptr<Board> board_;
  gl::FrameParser host_{gl::Accept::kDeviceToHost};
  gl::SequenceCounter seq_;

  uint32_t last_host_us_ = 0;
  uint64_t clock64_ = 0;            // device time since boot, unwrapped (real-time clock)
  uint64_t silence_us_ = 0;         // device time since the last POSE or SET_MOTORS
  uint64_t sample_silence_us_ = 0;  // device time since the last SIM_IMU_SAMPLE
  uint32_t last_sample_host_us_ = 0;
  uint32_t dither_ = 0;
  uint16_t upload_next_ = 0, upload_count_ = 0;  // the plan upload under way
  uint16_t trial_ids_ = 0;
  float scene_timeout_s_ = 0;  // of the last acknowledged SET_SCENE
  float trial_timeout_s_ = 0;
  uint16_t trial_id_ = 0;
  bool first_pose_seen_ = false;
  uint64_t first_pose_us_ = 0;
};

// ---- seeds ------------------------------------------------------------------------------------

// Writes inputs in the format Rig::run reads: a few sessions a real host would have.
class SeedWriter {
 public:
  explicit SeedWriter(uint8_t config) { b_.push_back(config); }
  SeedWriter& op(Op op, uint8_t flags = 0) {
    uint8_t slot = 0;
    while (kOpOfSlot[slot] != op) ++slot;
    b_.push_back(uint8_t(slot | flags << 5));
    return *this;
  }
  SeedWriter& bytes(std::initializer_list<uint8_t> v) {
    b_.insert(b_.end(), v);
    return *this;
  }
  // Template 0x20: k = 4, 2 s timeout, 0.5 s hold; no overrides.
  SeedWriter& scene(uint8_t t = 0x20) { return op(Op::kSetScene).bytes({t, 0}); }
  SeedWriter& trial() { return op(Op::kStartTrial).bytes({0, 0}); }
  // Pose template t (0: the goal orientation), time spec s (0: 10 ms later).
  SeedWriter& poses(int n, uint8_t t = 0, uint8_t s = 0) {
    for (int i = 0; i < n; ++i) op(Op::kPose).bytes({t, s, 0});
    return *this;
  }
  SeedWriter& advance(uint8_t spec) { return op(Op::kAdvance).bytes({spec}); }
  // Plan template t (0: one 90 s trial, no rest), its trials from template 0, no overrides.
  SeedWriter& plan(uint8_t t = 0) {
    op(Op::kPlanUpload).bytes({t, 0});
    for (int i = 0; i < 1 + (t & 3); ++i) bytes({0, 0});
    return *this;
  }
  // n samples of a still hand (template t), pressing the button when asked (flag 0x4), held
  // along the trial's force with flag 0x2.
  SeedWriter& samples(uint8_t n, uint8_t t = 0, uint8_t flags = 4) {
    return op(Op::kSimSamples, flags).bytes({t, uint8_t(n - 1)});
  }
  SeedWriter& store(uint8_t what, std::initializer_list<uint8_t> args = {}) {
    op(Op::kStore).bytes({what});
    return bytes(args);
  }
  const std::vector<uint8_t>& data() const { return b_; }

 private:
  std::vector<uint8_t> b_;
};

void write_seeds(const char* dir) {
  const uint8_t kFar = 4;                      // pose template: 90 deg off the goal
  const uint8_t kJump2e31 = 5 | (4 << 3);      // time spec: prev + 2^31
  const uint8_t kSeconds30 = 4 | (30 << 3);    // clock step: 30 s
  const uint8_t kStaleExactly = 1;             // clock step: the watchdog's time
  const uint8_t kHugeTimeout = 0 | (10 << 3);  // value: special 1e30
  struct Seed {
    const char* name;
    SeedWriter w;
  };
  std::vector<Seed> seeds;
  seeds.push_back({"trial_success", SeedWriter(0).scene().trial().poses(80)});
  seeds.push_back({"trial_timeout", SeedWriter(0).scene().trial().poses(220, kFar)});
  seeds.push_back({"pose_time_jump_2e31", SeedWriter(0)
                                              .scene()
                                              .trial()
                                              .poses(5, kFar)
                                              .poses(1, kFar, kJump2e31)
                                              .poses(5, kFar)
                                              .advance(kSeconds30)
                                              .poses(3, kFar)});
  seeds.push_back(
      {"trial_then_silence",
       SeedWriter(0).scene().trial().poses(5, kFar).advance(kStaleExactly).advance(kSeconds30)});
  seeds.push_back(
      {"set_motors_then_silence",
       SeedWriter(0).op(Op::kSetMotors).bytes({200, 200, 200, 200}).advance(kStaleExactly)});
  seeds.push_back({"refusal_during_trial", SeedWriter(0).scene().trial().poses(3, kFar).scene()});
  seeds.push_back({"stop_during_trial",
                   SeedWriter(0).scene().trial().poses(3, kFar).op(Op::kStop).op(Op::kGetStatus)});
  seeds.push_back({"half_frame_then_stop", SeedWriter(0)
                                               .scene()
                                               .trial()
                                               .poses(3, kFar)
                                               .op(Op::kGarbage)
                                               .bytes({5, 0x20, 0x01, 0x03, 0x07, 0x11})
                                               .op(Op::kStop, kFlagDelimiterFirst)});
  seeds.push_back({"huge_timeout", SeedWriter(0)
                                       .op(Op::kSetScene)
                                       .bytes({0x20, 1, 17, kHugeTimeout})
                                       .trial()
                                       .poses(3, kFar)
                                       .advance(kSeconds30)});
  seeds.push_back(
      {"bad_enum_in_trial",  // SET_SCENE with byte 61 (constraints) = 7
       SeedWriter(0).scene().trial().poses(3, kFar).op(Op::kRawFrame, 2).bytes({0, 0x20, 61, 7})});
  seeds.push_back({"virtual_clock_trial",
                   SeedWriter(1).scene().trial().poses(30, kFar).advance(kStaleExactly)});
  seeds.push_back({"clock_wrap_trial", SeedWriter(2).scene().trial().poses(250, kFar)});
  // The host-less runner and its store. Plan template 0x82: three 0.25 s trials, no rest.
  const uint8_t kShortPlan = 0x82;
  seeds.push_back({"hostless_run_to_the_end", SeedWriter(1)
                                                  .plan(kShortPlan)
                                                  .op(Op::kHostlessRun)
                                                  .samples(64)
                                                  .samples(64)
                                                  .samples(64)
                                                  .op(Op::kLogInfo)
                                                  .op(Op::kLogRead)
                                                  .bytes({0})
                                                  .op(Op::kLogRead)
                                                  .bytes({2})
                                                  .op(Op::kLogErase)});
  seeds.push_back({"hostless_success", SeedWriter(1)
                                           .plan(kShortPlan)
                                           .op(Op::kHostlessRun)
                                           .samples(64, 0, 6)
                                           .samples(64, 0, 6)
                                           .op(Op::kLogInfo)});
  seeds.push_back({"hostless_real_clock", SeedWriter(0)
                                              .plan(kShortPlan)
                                              .op(Op::kHostlessRun)
                                              .samples(64)
                                              .advance(kStaleExactly)
                                              .samples(64)
                                              .op(Op::kStop)});
  seeds.push_back({"error_during_ready_pattern", SeedWriter(1)
                                                     .plan(kShortPlan)
                                                     .op(Op::kHostlessRun)
                                                     .samples(2, 0, 0)
                                                     .scene()
                                                     .samples(10, 0, 0)
                                                     .op(Op::kLogInfo)});
  seeds.push_back({"garbage_during_end_pattern", SeedWriter(1)
                                                     .plan(kShortPlan)
                                                     .op(Op::kHostlessRun)
                                                     .samples(64)
                                                     .samples(30)
                                                     .op(Op::kGarbage)
                                                     .bytes({4, 0x13, 0x00, 0x37, 0x00})
                                                     .samples(10)});
  seeds.push_back({"erase_and_commit_while_motors_run", SeedWriter(0)
                                                            .plan(kShortPlan)
                                                            .op(Op::kSetMotors)
                                                            .bytes({200, 200, 200, 200})
                                                            .op(Op::kLogErase)
                                                            .op(Op::kSetMotors)
                                                            .bytes({200, 200, 200, 200})
                                                            .plan(kShortPlan)
                                                            .scene()
                                                            .trial()
                                                            .poses(3, kFar)
                                                            .op(Op::kLogErase)
                                                            .plan(kShortPlan)});
  seeds.push_back({"power_cut_during_append", SeedWriter(1)
                                                  .plan(kShortPlan)
                                                  .op(Op::kHostlessRun)
                                                  .store(0, {40, 0})
                                                  .samples(64)
                                                  .samples(64)
                                                  .store(3)
                                                  .store(4)
                                                  .op(Op::kLogInfo)
                                                  .op(Op::kHostlessRun)
                                                  .samples(64)});
  seeds.push_back({"flipped_bit_then_reboot", SeedWriter(1)
                                                  .plan(kShortPlan)
                                                  .op(Op::kHostlessRun)
                                                  .samples(64)
                                                  .samples(64)
                                                  .store(5, {0x93, 0x04, 3})
                                                  .store(4)
                                                  .op(Op::kLogInfo)
                                                  .op(Op::kHostlessRun)
                                                  .samples(64)});
  seeds.push_back(
      {"no_hostless_board",
       SeedWriter(4).plan(kShortPlan).op(Op::kHostlessRun).op(Op::kLogInfo).samples(3)});
  for (const Seed& s : seeds) {
    const std::string path = std::string(dir) + "/" + s.name;
    FILE* f = std::fopen(path.c_str(), "wb");
    if (!f || std::fwrite(s.w.data().data(), 1, s.w.data().size(), f) != s.w.data().size() ||
        std::fclose(f) != 0) {
      std::fprintf(stderr, "fuzz_device: cannot write seed %s\n", path.c_str());
      std::exit(2);
    }
  }
  std::printf("fuzz_device: %zu seeds written to %s\n", seeds.size(), dir);
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = std::getenv("GRASPGUIDE_FUZZ_WRITE_SEEDS")) {
    write_seeds(dir);
    std::exit(0);
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Input in(data, size);
  auto rig = std::make_unique<Rig>(in.u8());
  rig->run(in);
  return 0;
}
