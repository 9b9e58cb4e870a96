// The per-frame-only board: the host solves each posture (SET_POSTURE) and the board does
// the per-frame work on streamed poses (error, alpha, PWM, the trial, the watchdog). Every
// request is answered as lib/graspguide_device's LinkDevice answers it, except what needs the
// full solve: SET_SCENE and POSE contacts are per_frame_only. Portable: a board gives it a
// ByteStream, its MotorOutputs and a Clock (graspguide_hal).
#pragma once

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#include "graspguide_cue.h"
#include "graspguide_cue_device/link_subset.h"
#include "graspguide_cue_device/parser.h"
#include "graspguide_hal/hal.h"
#include "graspguide_hal/link_poll.h"

#ifndef GRASPGUIDE_STALE_TIMEOUT_MS
#define GRASPGUIDE_STALE_TIMEOUT_MS 200  // no POSE for this long: motors off
#endif
#ifndef GRASPGUIDE_TRIAL_CLOCK_SLACK_MS
// How far the board's own clock may run past timeout_s before it ends a trial whose pose
// timestamps stopped advancing (as graspguide_device/application.h).
#define GRASPGUIDE_TRIAL_CLOCK_SLACK_MS 1000
#endif

namespace graspguide {
namespace cue_device {

constexpr uint32_t kStaleTimeoutUs = uint32_t(GRASPGUIDE_STALE_TIMEOUT_MS) * 1000u;
constexpr uint32_t kTrialClockSlackUs = uint32_t(GRASPGUIDE_TRIAL_CLOCK_SLACK_MS) * 1000u;
// A unit force direction, rounded to float32 by the host: |f|^2 is within a few ulp of 1.
constexpr float kForceUnitSlack = 1e-4f;

static_assert(link::kMaxContacts == graspguide::kMaxContacts, "contact slots");

struct DeviceInfo {
  uint8_t firmware_version[3] = {0, 1, 0};
  const char* board = "promini";
  uint32_t build_id = 0;
};

class CueDevice {
 public:
  using State = link::DeviceState;

  CueDevice(hal::ByteStream& stream, hal::MotorOutputs& motors, hal::Clock& clock,
            const DeviceInfo& info)
      : stream_(stream), motors_(motors), clock_(clock), info_(info) {
    motors_off();  // whatever the pins did before boot
  }

  // Reads what the stream has, handles every complete frame, runs the watchdog and the
  // trial's own clock. Returns the number of bytes read.
  size_t poll() {
    uint32_t now_us;
    const size_t total = link_poll_.receive<16>(*this, now_us);
    tick();
    return total;
  }

  State state() const { return state_; }
  bool motors_on() const { return motors_on_; }
  uint32_t stale_events() const { return stale_events_; }
  const FrameParser& parser() const { return parser_; }

 private:
  friend class hal::LinkPoll;
  hal::ByteStream& link_stream() { return stream_; }
  hal::Clock& link_clock() { return clock_; }
  FrameParser& link_parser() { return parser_; }
  void on_link_event(ParseEvent event) { handle(event); }

  void handle(ParseEvent event) {
    if (event == ParseEvent::kNone) return;
    const FrameHeader& h = parser_.frame().header;
    if (event != ParseEvent::kFrame) {
      motors_off();  // whatever the frame was, it was not what the host meant to send
      // Only frames whose header passed the CRC are answered: their seq can be trusted.
      if (event == ParseEvent::kBadVersion)
        send_error(h.seq, link::ErrorCode::kBadVersion, h.version);
      else if (event == ParseEvent::kUnknownId)
        send_error(h.seq, link::ErrorCode::kUnknownId, h.msg_id);
      else if (event == ParseEvent::kBadLength)
        send_error(h.seq, link::ErrorCode::kBadLength, h.msg_id);
      return;
    }
    request_seq_ = h.seq;
    const uint8_t* p = parser_.frame().payload;
    uint8_t bad_field = 0;
    bool ok = true;
    switch (h.msg_id) {
      case link::Hello::kId: {
        link::Hello m;
        if ((ok = link::unpack(p, &m, &bad_field))) on_hello();
        break;
      }
      case link::SetPosture::kId: {
        link::SetPosture m;
        if ((ok = link::unpack(p, &m, &bad_field))) on_set_posture(m);
        break;
      }
      case link::SetCalibration::kId: {
        link::SetCalibration m;
        if ((ok = link::unpack(p, &m, &bad_field))) on_set_calibration(m);
        break;
      }
      case link::StartTrial::kId: {
        link::StartTrial m;
        if ((ok = link::unpack(p, &m, &bad_field))) on_start_trial(m);
        break;
      }
      case link::Pose::kId: {
        link::Pose m;
        if ((ok = link::unpack(p, &m, &bad_field))) on_pose(m);
        break;
      }
      case link::Stop::kId:
        on_stop();
        break;
      case link::SetMotors::kId: {
        link::SetMotors m;
        if ((ok = link::unpack(p, &m, &bad_field))) on_set_motors(m);
        break;
      }
      case link::GetStatus::kId:
        on_get_status();
        break;
      default:
        // A message of the full-solve device, a simulator, or a board with storage or an IMU.
        send_error(request_seq_, link::refusal_of(h.msg_id), h.msg_id);
        break;
    }
    if (!ok) send_error(request_seq_, link::ErrorCode::kBadEnumValue, bad_field);
  }

  // ---- requests
  void on_hello() {
    link::HelloReply r;
    r.request_seq = request_seq_;
    r.protocol_version = link::kProtocolVersion;
    memcpy(r.firmware_version, info_.firmware_version, sizeof r.firmware_version);
    // NUL-padded, not NUL-terminated: a 16-character name fills the field.
    for (size_t i = 0; i < sizeof r.board && info_.board[i] != '\0'; ++i)
      r.board[i] = info_.board[i];
    r.scalar = sizeof(float);
    r.max_contacts = link::kMaxContacts;
    r.build_id = info_.build_id;
    r.capabilities = link::kCapabilityPerFrame;
    send(r);
  }

  static bool finite(float x) { return graspguide::scalar_math::is_finite(x); }

  // The field that makes the posture unusable, or 0xFF. The host computed it with the same
  // core, so a bad one is a host bug or a corrupted request, never something to render.
  static uint8_t bad_posture_field(const link::SetPosture& m) {
    using P = link::SetPosture;
    if (m.k < graspguide::kMinContacts || m.k > graspguide::kMaxContacts) return P::kFieldK;
    bool any_on = false;
    for (uint8_t i = 0; i < graspguide::kMaxContacts; ++i) {
      const float l = m.levels[i];
      if (!finite(l) || l < 0.0f || l > 1.0f || (i >= m.k && l != 0.0f)) return P::kFieldLevels;
      any_on = any_on || l > float(graspguide::kMotorOffLevel);
    }
    if (!any_on) return P::kFieldLevels;  // nothing to display
    float n2 = 0.0f;
    for (uint8_t i = 0; i < 3; ++i) {
      if (!finite(m.force_unit[i])) return P::kFieldForceUnit;
      n2 += m.force_unit[i] * m.force_unit[i];
    }
    if (!(graspguide::scalar_math::abs_of(n2 - 1.0f) <= kForceUnitSlack)) return P::kFieldForceUnit;
    for (uint8_t i = 0; i < 6; ++i)
      if (!finite(m.wrench[i])) return P::kFieldWrench;
    graspguide::TrialField trial_field = graspguide::TrialField::kNone;
    graspguide::TrialConfig config;
    config.threshold_deg = m.threshold_deg;
    config.hold_s = m.hold_s;
    config.timeout_s = m.timeout_s;
    graspguide::validate_trial_config(config, &trial_field);
    switch (trial_field) {
      case graspguide::TrialField::kThresholdDeg:
        return P::kFieldThresholdDeg;
      case graspguide::TrialField::kHoldS:
        return P::kFieldHoldS;
      case graspguide::TrialField::kTimeoutS:
        return P::kFieldTimeoutS;
      case graspguide::TrialField::kNone:
        break;
    }
    return 0xFF;
  }

  // A new posture; refused while a trial runs. An invalid one is reported and the previous
  // valid posture stays.
  void on_set_posture(const link::SetPosture& m) {
    if (state_ == State::kTrialRunning) return refuse_in_state();
    const uint8_t bad = bad_posture_field(m);
    if (bad != 0xFF) return send_error(request_seq_, link::ErrorCode::kBadConfig, bad);
    memcpy(levels_, m.levels, sizeof levels_);
    k_ = m.k;
    plan_ = graspguide::plan_pwm(levels_, k_, calibration_);
    mode_ = graspguide::Mode(m.mode);
    memcpy(force_unit_, m.force_unit, sizeof force_unit_);
    memcpy(wrench_, m.wrench, sizeof wrench_);
    trial_config_.threshold_deg = m.threshold_deg;
    trial_config_.hold_s = m.hold_s;
    trial_config_.timeout_s = m.timeout_s;
    state_ = State::kSceneSet;
    ack();
  }

  // The participant's per-motor PWM floor and gain, for the posture set and every later
  // one (SET_MOTORS stays raw). Refused while a trial runs; an invalid one is refused with
  // the field's index and the previous one stays.
  void on_set_calibration(const link::SetCalibration& m) {
    if (state_ == State::kTrialRunning) return refuse_in_state();
    graspguide::MotorCalibration c;
    memcpy(c.pwm_floor, m.pwm_floor, sizeof c.pwm_floor);
    memcpy(c.gain, m.gain, sizeof c.gain);
    const graspguide::CalibrationCheck check = graspguide::check_calibration(c);
    if (check != graspguide::CalibrationCheck::kOk) {
      const bool gain = graspguide::calibration_field(check) == graspguide::CalibrationField::kGain;
      return send_error(
          request_seq_, link::ErrorCode::kBadConfig,
          gain ? link::SetCalibration::kFieldGain : link::SetCalibration::kFieldPwmFloor);
    }
    calibration_ = c;
    plan_ = graspguide::plan_pwm(levels_, k_, calibration_);
    ack();
  }

  void on_start_trial(const link::StartTrial& m) {
    if (state_ == State::kIdle)
      return send_error(request_seq_, link::ErrorCode::kNoScene, link::StartTrial::kId);
    if (state_ == State::kTrialRunning) return refuse_in_state();
    // Bit for bit: the levels were solved for exactly this wrench.
    if (memcmp(m.wrench, wrench_, sizeof wrench_) != 0)
      return send_error(request_seq_, link::ErrorCode::kPostureMismatch, 0);
    trial_id_ = m.trial_id;
    trial_started_ = false;  // the trial's clock starts with its first pose
    state_ = State::kTrialRunning;
    ack();
  }

  void on_pose(const link::Pose& m) {
    if (m.has_contacts)
      return send_error(request_seq_, link::ErrorCode::kPerFrameOnly, link::Pose::kId);
    if (state_ == State::kIdle)
      return send_error(request_seq_, link::ErrorCode::kNoScene, link::Pose::kId);
    watchdog_.feed(clock_.now_us());
    stale_ = false;
    if (state_ != State::kTrialRunning) return refuse_in_state();  // no wrench to render
    link::Telemetry t;
    t.host_time_us = m.host_time_us;
    // The trial's clocks start with its first POSE, even one that fails below.
    const int64_t t_us =
        trial_started_ ? timeline_.advance(m.host_time_us) : timeline_.restart(m.host_time_us);
    if (!trial_started_) {
      trial_.start(trial_config_, t_us);
      trial_started_ = true;
      deadline_.start(clock_.now_us(), trial_config_.timeout_s, kTrialClockSlackUs);
    } else if (t_us < trial_last_us_) {
      // The host's timeline can no longer be trusted to end the trial: it ends here.
      abort_trial();
      return send_error(request_seq_, link::ErrorCode::kTimeWentBackwards, uint8_t(state_));
    }
    trial_last_us_ = t_us;
    const uint32_t t0 = clock_.now_us();
    graspguide::Alignment<float> a;
    graspguide::Status s = graspguide::alignment_from_quaternion(m.quat_wxyz, force_unit_, a);
    graspguide::Pwm pwm;
    if (s == graspguide::Status::kOk)
      pwm = graspguide::pwm_from_plan(plan_, graspguide::pwm_gain(mode_, a.alpha));
    t.compute_time_us = clock_.now_us() - t0;
    if (s == graspguide::Status::kOk) s = trial_.update(t_us, double(a.error_deg));
    if (s != graspguide::Status::kOk) {
      // A failed POSE does not end the trial: the flag says it still runs.
      motors_off();
      t.solver_status = link::error_code_of(s);
      t.flags = link::kTelemetryFlagTrialRunning;
      last_error_ = t.solver_status;
      send(t);
      return;
    }
    t.error_deg = a.error_deg;
    t.alpha = a.alpha;
    if (!trial_.running()) {
      motors_off();
      state_ = State::kSceneSet;
      send(t);
      send_trial_result();
      return;
    }
    write_motors(pwm);
    memcpy(t.pwm, pwm.duty, sizeof t.pwm);
    t.flags = link::kTelemetryFlagTrialRunning;
    send(t);
  }

  void on_stop() {
    motors_off();
    abort_trial();
    ack();
  }

  // Direct PWM for calibration; the watchdog still switches it off without poses.
  void on_set_motors(const link::SetMotors& m) {
    if (state_ == State::kTrialRunning) return refuse_in_state();
    graspguide::Pwm pwm;
    memcpy(pwm.duty, m.pwm, sizeof pwm.duty);
    write_motors(pwm);
    watchdog_.feed(clock_.now_us());
    ack();
  }

  void on_get_status() {
    link::Status s;
    s.state = state_;
    s.frames_received = parser_.good_frames();
    s.bad_frames = parser_.bad_frames();
    s.stale_events = stale_events_;
    s.last_error = last_error_;
    send(s);
  }

  // ---- the board's own clock
  void tick() {
    const uint32_t now = clock_.now_us();
    if (motors_on_ && watchdog_.expired(now)) {
      motors_off();
      if (!stale_) ++stale_events_;
      stale_ = true;
    }
    if (state_ != State::kTrialRunning || !trial_started_) return;
    if (!deadline_.passed(now)) return;
    trial_.expire();
    motors_off();
    state_ = State::kSceneSet;
    send_trial_result();
  }

  // ---- motors and state
  void write_motors(const graspguide::Pwm& pwm) {
    motors_.write(pwm);
    motors_on_ = false;
    for (uint8_t d : pwm.duty) motors_on_ = motors_on_ || d != 0;
  }

  void motors_off() {
    motors_.write(graspguide::Pwm{});
    motors_on_ = false;
  }

  void abort_trial() {
    trial_.abort();
    if (state_ != State::kIdle) state_ = State::kStopped;
  }

  // ---- replies
  void ack() {
    link::Ack a;
    a.request_seq = request_seq_;
    send(a);
  }

  void refuse_in_state() {
    send_error(request_seq_, link::ErrorCode::kNotAllowedInState, uint8_t(state_));
  }

  // Every ERROR turns the motors off: a host whose request failed has lost track of what
  // the wearer feels, so nothing keeps vibrating on a stale command.
  void send_error(uint16_t seq, link::ErrorCode code, uint8_t detail) {
    motors_off();
    link::Error e;
    e.request_seq = seq;
    e.code = code;
    e.detail = detail;
    last_error_ = code;
    send(e);
  }

  void send_trial_result() {
    const graspguide::TrialResult& result = trial_.result();
    link::TrialResult r;
    r.trial_id = trial_id_;
    r.success = result.success;
    r.completion_s = float(result.completion_s);
    r.first_entry_s = float(result.first_entry_s);
    r.final_error_deg = float(result.final_error_deg);
    send(r);
  }

  // Header, payload and CRC in one small stack buffer, COBS-encoded straight to the stream.
  template <class Msg>
  void send(const Msg& m) {
    uint8_t raw[link::kHeaderSize + link::kMaxSentPayloadSize + link::kCrcSize];
    static_assert(Msg::kPayloadSize <= link::kMaxSentPayloadSize, "generated sizes disagree");
    const uint16_t seq = next_seq_++;
    raw[0] = link::kProtocolVersion;
    raw[1] = Msg::kId;
    raw[2] = uint8_t(seq);
    raw[3] = uint8_t(seq >> 8);
    link::pack(m, raw + link::kHeaderSize);
    const size_t crc_at = link::kHeaderSize + Msg::kPayloadSize;
    uint16_t crc = link::kCrc16Init;
    for (size_t i = 0; i < crc_at; ++i) crc = link::crc16_update(crc, raw[i]);
    raw[crc_at] = uint8_t(crc);
    raw[crc_at + 1] = uint8_t(crc >> 8);
    link::cobs_write(raw, crc_at + link::kCrcSize,
                     [this](const uint8_t* data, size_t n) { stream_.write(data, n); });
  }

  hal::ByteStream& stream_;
  hal::MotorOutputs& motors_;
  hal::Clock& clock_;
  DeviceInfo info_;
  FrameParser parser_;
  // The posture, as the host solved it, and the participant's calibration.
  float levels_[graspguide::kMaxContacts] = {0.0f, 0.0f, 0.0f, 0.0f};
  uint8_t k_ = 0;
  graspguide::MotorCalibration calibration_;
  graspguide::PwmPlan<float> plan_;
  float force_unit_[3] = {0.0f, 0.0f, 0.0f};
  float wrench_[6] = {0.0f, 0.0f, 0.0f, 0.0f, 0.0f, 0.0f};
  graspguide::Mode mode_ = graspguide::Mode::kC;
  graspguide::TrialConfig trial_config_;
  // The trial and the clocks.
  graspguide::Trial trial_;
  graspguide::HostTimeline timeline_;
  graspguide::TrialDeadline deadline_;
  graspguide::PoseWatchdog watchdog_{kStaleTimeoutUs};
  int64_t trial_last_us_ = 0;
  State state_ = State::kIdle;
  uint16_t trial_id_ = 0;
  bool trial_started_ = false;
  bool motors_on_ = false;
  bool stale_ = false;
  uint16_t request_seq_ = 0;
  uint16_t next_seq_ = 0;
  hal::LinkPoll link_poll_;
  uint32_t stale_events_ = 0;
  link::ErrorCode last_error_ = link::ErrorCode::kOk;
};

}  // namespace cue_device
}  // namespace graspguide
