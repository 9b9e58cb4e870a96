// The device end of the serial link: bytes in, frames parsed, requests turned into
// Application calls, replies and telemetry framed and written. Portable: a board gives it a
// ByteStream; the simulated device gives it a pseudo-terminal.
#pragma once

#include <cstring>

#include "graspguide_device/application.h"
#include "graspguide_device/hostless_app.h"
#include "graspguide_hal/link_poll.h"
#include "graspguide_link/core_status.h"
#include "graspguide_link/parser.h"
#include "graspguide_link/writer.h"

namespace graspguide::device {

// SET_SCENE's field index of a trial field (ERROR.detail of bad_config), found by name in
// the schema's field list so the two cannot drift apart.
inline uint8_t set_scene_field_index(TrialField f) {
  const char* key = trial_field_range(f).key;
  uint8_t i = 0, found = 0;
  link::for_each_field(link::SetScene{}, [&](const char* name, const auto&) {
    if (std::strcmp(name, key) == 0) found = i;
    ++i;
  });
  return found;
}

// A message's field index by name (ERROR.detail of bad_config), from the schema's list.
template <class Msg>
uint8_t link_field_index(const Msg& m, const char* key) {
  uint8_t i = 0, found = 0;
  link::for_each_field(m, [&](const char* name, const auto&) {
    if (std::strcmp(name, key) == 0) found = i;
    ++i;
  });
  return found;
}

static_assert(uint8_t(link::DeviceState::kTrialRunning) == uint8_t(DeviceState::kTrialRunning) &&
                  uint8_t(link::DeviceState::kStopped) == uint8_t(DeviceState::kStopped),
              "device states must match the protocol schema");
static_assert(link::kMaxContacts == kMaxContacts, "contact slots must match the schema");
static_assert(link::kMaxPlanTrials == kMaxPlanTrials, "plan size must match the schema");
static_assert(uint8_t(link::RunEvent::kImuFault) == uint8_t(RunEventCode::kImuFault) &&
                  uint8_t(link::RunEvent::kPlanDone) == uint8_t(RunEventCode::kPlanDone),
              "run events must match the protocol schema");

struct DeviceInfo {
  uint8_t firmware_version[3] = {0, 1, 0};
  const char* board = "unknown";
  uint32_t build_id = 0;
  uint8_t capabilities = link::kCapabilityFullSolve;  // link::kCapability* bits
};

// Told the host time of every POSE before it is handled: the simulated device's virtual
// clock follows it.
class PoseTimeListener {
 public:
  virtual void on_pose_time(uint32_t host_time_us) = 0;

 protected:
  ~PoseTimeListener() = default;
};

class LinkDevice {
 public:
  // hostless: the host-less runner of a board that has storage (and an IMU), else nullptr
  // (the PLAN_*, LOG_* and HOSTLESS_RUN requests are then unknown_id). pose_time also
  // hears SIM_IMU_SAMPLE's time.
  LinkDevice(hal::ByteStream& stream, Application& app, const DeviceInfo& info,
             PoseTimeListener* pose_time = nullptr, HostlessRunner* hostless = nullptr)
      : stream_(stream), app_(app), info_(info), pose_time_(pose_time), hostless_(hostless) {}

  // Reads what the stream has, handles every complete frame, runs the watchdog.
  // Returns the number of bytes read.
  size_t poll() {
    uint32_t now;
    const size_t total = link_poll_.receive<64>(*this, now);
    TrialReport report;
    if (app_.tick(&report)) send_trial_result(report);
    if (hostless_) {
      hostless_->tick(now);
      send_hostless_news();
    }
    return total;
  }

  const link::FrameParser& parser() const { return parser_; }

 private:
  friend class hal::LinkPoll;
  hal::ByteStream& link_stream() { return stream_; }
  hal::Clock& link_clock() { return app_.clock(); }
  link::FrameParser& link_parser() { return parser_; }
  void on_link_event(link::ParseEvent event) { handle(event); }

  void handle(link::ParseEvent event) {
    if (event == link::ParseEvent::kNone) return;
    link::ErrorCode code;
    if (event != link::ParseEvent::kFrame) {
      all_motors_off();  // whatever the frame was, it was not what the host meant to send
      // Only frames whose header passed the CRC are answered: their seq can be trusted.
      if (link::has_trusted_header(event) && link::error_code_for(event, &code)) {
        const auto& h = parser_.frame().header;
        send_error(h.seq, code, event == link::ParseEvent::kBadVersion ? h.version : h.msg_id);
      }
      return;
    }
    const link::FrameView& f = parser_.frame();
    request_seq_ = f.header.seq;
    uint8_t bad_field = 0;
    const link::LinkStatus s = link::visit_payload(
        f.header.msg_id, f.payload, f.payload_size, [this](const auto& m) { on(m); }, &bad_field);
    if (s == link::LinkStatus::kBadEnumValue)
      send_error(request_seq_, link::ErrorCode::kBadEnumValue, bad_field);
    else if (s != link::LinkStatus::kOk)
      send_error(request_seq_, link::ErrorCode::kBadLength, f.header.msg_id);
  }

  // ---- requests
  void on(const link::Hello&) {
    link::HelloReply r;
    r.request_seq = request_seq_;
    r.protocol_version = link::kProtocolVersion;
    std::memcpy(r.firmware_version, info_.firmware_version, sizeof r.firmware_version);
    // NUL-padded, not NUL-terminated: a 16-character name fills the field (r.board starts
    // zeroed). A loop, since strncpy with that bound is what -Wstringop-truncation flags.
    for (size_t i = 0; i < sizeof r.board && info_.board[i] != '\0'; ++i)
      r.board[i] = info_.board[i];
    r.scalar = sizeof(Real);
    r.max_contacts = kMaxContacts;
    r.build_id = info_.build_id;
    r.capabilities = info_.capabilities;
    send(r);
  }

  // While the wearable runs its plan, the tracker-driven requests would fight it for the
  // motors: refused until STOP.
  bool hostless_busy() {
    if (!hostless_ || !hostless_->running()) return false;
    send_error(request_seq_, link::ErrorCode::kNotAllowedInState, uint8_t(app_.state()));
    return true;
  }

  void on(const link::SetScene& m) {
    if (hostless_busy()) return;
    Scene<Real> scene;
    scene.k = m.k;
    for (int i = 0; i < kMaxContacts; ++i)
      for (int j = 0; j < 3; ++j) scene.contacts(j, i) = m.contacts[i][j];
    scene.y_axis = Vec3<Real>(m.y_axis[0], m.y_axis[1], m.y_axis[2]);
    scene.constraints = static_cast<ConstraintModel>(m.constraints);
    scene.policy = static_cast<Policy>(m.policy);
    scene.mode = static_cast<Mode>(m.mode);
    scene.trial.threshold_deg = m.threshold_deg;
    scene.trial.hold_s = m.hold_s;
    scene.trial.timeout_s = m.timeout_s;
    TrialField bad = TrialField::kNone;
    const Reply reply = app_.set_scene(scene, &bad);
    if (reply.status == Status::kBadConfig && bad != TrialField::kNone)
      send_error(request_seq_, link::ErrorCode::kBadConfig, set_scene_field_index(bad));
    else
      answer(reply, link::MsgId::kSetScene);
  }

  void on(const link::StartTrial& m) {
    if (hostless_busy()) return;
    Vec6<Real> w;
    for (int j = 0; j < 6; ++j) w(j) = m.wrench[j];
    answer(app_.start_trial(m.trial_id, w), link::MsgId::kStartTrial);
  }

  void on(const link::Pose& m) {
    if (hostless_busy()) return;
    if (pose_time_) {
      pose_time_->on_pose_time(m.host_time_us);
      // A jump in virtual time is a silence the watchdog and the trial's clock must see.
      TrialReport expired;
      if (app_.tick(&expired)) send_trial_result(expired);
    }
    PoseIn in;
    in.host_time_us = m.host_time_us;
    in.quat_wxyz =
        Eigen::Matrix<Real, 4, 1>(m.quat_wxyz[0], m.quat_wxyz[1], m.quat_wxyz[2], m.quat_wxyz[3]);
    in.has_contacts = m.has_contacts;
    for (int i = 0; i < kMaxContacts; ++i)
      for (int j = 0; j < 3; ++j) in.contacts(j, i) = m.contacts[i][j];
    Telemetry tel;
    TrialReport report;
    bool ended = false;
    const Reply reply = app_.pose(in, tel, report, ended);
    if (reply.refusal != Refusal::kNone) {
      answer(reply, link::MsgId::kPose);
      return;
    }
    link::Telemetry t;
    t.host_time_us = tel.host_time_us;
    t.error_deg = tel.error_deg;
    t.alpha = tel.alpha;
    for (int i = 0; i < kMaxContacts; ++i) t.pwm[i] = tel.pwm.duty[i];
    t.constraints_used = static_cast<link::ConstraintModel>(tel.used);
    t.solver_status = link::error_code_of(tel.status);
    t.iterations = tel.iterations;
    t.flags = uint8_t((tel.recomputed ? link::kTelemetryFlagGraspRecomputed : 0) |
                      (tel.trial_running ? link::kTelemetryFlagTrialRunning : 0));
    t.compute_time_us = tel.compute_time_us;
    if (tel.status != Status::kOk) last_error_ = t.solver_status;
    send(t);
    if (ended) send_trial_result(report);
  }

  void send_trial_result(const TrialReport& report) {
    link::TrialResult r;
    r.trial_id = report.trial_id;
    link::copy_trial_result_fields(report.result, r);
    send(r);
  }

  void on(const link::Stop&) {
    if (hostless_) hostless_->stop();
    app_.stop();
    answer(Reply{}, link::MsgId::kStop);
  }

  void on(const link::SetMotors& m) {
    if (hostless_busy()) return;
    Pwm pwm;
    for (int i = 0; i < kMaxContacts; ++i) pwm.duty[i] = m.pwm[i];
    answer(app_.set_motors(pwm), link::MsgId::kSetMotors);
  }

  void on(const link::GetStatus&) {
    link::Status s;
    s.state = static_cast<link::DeviceState>(app_.state());
    s.frames_received = parser_.good_frames();
    s.bad_frames = parser_.bad_frames();
    s.stale_events = app_.counters().stale_events;
    s.last_error = last_error_;
    send(s);
  }

  // This application solves every posture itself (kCapabilityFullSolve); SET_POSTURE is
  // for boards that do only the per-frame work.
  void on(const link::SetPosture&) {
    send_error(request_seq_, link::ErrorCode::kUnknownId, uint8_t(link::MsgId::kSetPosture));
  }

  void on(const link::SetCalibration& m) {
    if (hostless_busy()) return;
    MotorCalibration c;
    link::copy_calibration_fields(m, c);
    CalibrationField bad = CalibrationField::kNone;
    const Reply reply = app_.set_calibration(c, &bad);
    if (reply.status == Status::kBadConfig)
      send_error(request_seq_, link::ErrorCode::kBadConfig, calibration_field_index(bad));
    else
      answer(reply, link::MsgId::kSetCalibration);
  }

  static uint8_t calibration_field_index(CalibrationField f) {
    return link_field_index(link::SetCalibration{},
                            f == CalibrationField::kGain ? "gain" : "pwm_floor");
  }

  // ---- host-less: the plan, the run, the log
  bool hostless_missing(link::MsgId id) {
    if (hostless_) return false;
    send_error(request_seq_, link::ErrorCode::kUnknownId, uint8_t(id));
    return true;
  }

  // The plan upload and LOG_ERASE write the store, and PLAN_COMMIT first solves every
  // trial: on a large store that blocks the loop for seconds, and nothing runs the watchdog
  // meanwhile. So they are refused while anything drives the motors: a tracker trial (from
  // START_TRIAL on), SET_MOTORS not yet timed out, or a host-less run.
  bool motors_in_use() {
    const bool busy =
        app_.state() == DeviceState::kTrialRunning || app_.motors_on() || hostless_->running();
    if (busy) send_error(request_seq_, link::ErrorCode::kNotAllowedInState, uint8_t(app_.state()));
    return busy;
  }

  void on(const link::PlanBegin& m) {
    if (hostless_missing(link::MsgId::kPlanBegin) || motors_in_use()) return;
    PlanHeader h;
    link::copy_plan_begin_fields(m, h);
    answer(hostless_->begin_plan(h), link::MsgId::kPlanBegin);
  }

  void on(const link::PlanTrial& m) {
    if (hostless_missing(link::MsgId::kPlanTrial) || motors_in_use()) return;
    PlanTrial t;
    link::copy_plan_trial_fields(m, t);
    answer(hostless_->add_trial(m.position, t), link::MsgId::kPlanTrial);
  }

  void on(const link::PlanCommit& m) {
    if (hostless_missing(link::MsgId::kPlanCommit) || motors_in_use()) return;
    all_motors_off();  // whatever else changes: nothing may vibrate while the loop blocks
    answer(hostless_->commit_plan(m.trial_count), link::MsgId::kPlanCommit);
  }

  void on(const link::HostlessRun&) {
    if (hostless_missing(link::MsgId::kHostlessRun)) return;
    if (app_.state() == DeviceState::kTrialRunning) {
      send_error(request_seq_, link::ErrorCode::kNotAllowedInState, uint8_t(app_.state()));
      return;
    }
    app_.motors_off();
    answer(hostless_->start(), link::MsgId::kHostlessRun);
    send_hostless_news();
  }

  void on(const link::LogInfoGet&) {
    if (hostless_missing(link::MsgId::kLogInfoGet)) return;
    link::LogInfo r;
    r.plan_stored = hostless_->plan_stored();
    if (r.plan_stored) {
      const PlanHeader& h = hostless_->plan().header;
      std::memcpy(r.participant, h.participant, sizeof r.participant);
      r.simulated = h.simulated;
      std::memcpy(r.config_hash, h.config_hash, sizeof r.config_hash);
      r.plan_trials = h.trial_count;
    }
    ResultsLog& log = hostless_->log();
    r.records = log.records();
    r.capacity = log.capacity();
    r.torn_records = log.torn();
    r.running = hostless_->running();
    send(r);
  }

  void on(const link::LogRead& m) {
    if (hostless_missing(link::MsgId::kLogRead)) return;
    LogRecord rec;
    const StoreStatus s = hostless_->log().read(m.index, rec);
    if (s != StoreStatus::kOk) {
      send_error(request_seq_,
                 s == StoreStatus::kNoRecord ? link::ErrorCode::kNoRecord
                                             : link::ErrorCode::kStorageFailed,
                 0);
      return;
    }
    link::LogRecord r;
    r.index = m.index;
    link::copy_plan_trial_fields(rec.trial, r);
    link::copy_log_record_result_fields(rec, r);
    send(r);
  }

  void on(const link::LogErase& m) {
    if (hostless_missing(link::MsgId::kLogErase) || motors_in_use()) return;
    if (m.key != link::kLogEraseKey) {
      send_error(request_seq_, link::ErrorCode::kBadPlan, 0);
      return;
    }
    all_motors_off();  // whatever else changes: nothing may vibrate while the loop blocks
    if (hostless_->log().erase() != StoreStatus::kOk) {
      send_error(request_seq_, link::ErrorCode::kStorageFailed, 0);
    } else {
      answer(Reply{}, link::MsgId::kLogErase);
    }
  }

  // Only a simulated device takes the world's samples and presses from the host; a real
  // board has its own IMU and button, and a host pretending otherwise is an error.
  bool refuse_sim_only(link::MsgId id) {
    if (hostless_ && (info_.capabilities & link::kCapabilitySimMessages)) return false;
    send_error(request_seq_, link::ErrorCode::kSimOnly, uint8_t(id));
    return true;
  }

  void on(const link::SimImuSample& m) {
    if (refuse_sim_only(link::MsgId::kSimImuSample)) return;
    if (pose_time_) pose_time_->on_pose_time(m.time_us);
    const bool was_running = hostless_->running();
    hal::ImuSample s;
    s.time_us = app_.now_us();
    link::copy_imu_sample_fields(m, s);
    const HostlessFrame f = hostless_->on_sample(s);
    // What the sample caused goes first, so a host that has this sample's answer has heard
    // everything before it.
    send_hostless_news();
    if (!was_running) {
      answer(Reply{}, link::MsgId::kSimImuSample);
      return;
    }
    link::Telemetry t;
    t.host_time_us = m.time_us;
    t.error_deg = float(f.error_deg);
    t.alpha = float(f.alpha);
    for (int i = 0; i < kMaxContacts; ++i) t.pwm[i] = f.pwm.duty[i];
    t.constraints_used = static_cast<link::ConstraintModel>(hostless_->plan().header.constraints);
    t.solver_status = link::error_code_of(f.status);
    t.flags = uint8_t(f.trial_running ? link::kTelemetryFlagTrialRunning : 0);
    if (f.status != Status::kOk) last_error_ = t.solver_status;
    send(t);
  }

  void on(const link::SimButton& m) {
    if (refuse_sim_only(link::MsgId::kSimButton)) return;
    hostless_->on_button(m.pressed, app_.now_us());
    answer(Reply{}, link::MsgId::kSimButton);
    send_hostless_news();
  }

  void send_hostless_news() {
    RunEvent e;
    while (hostless_->pop_event(e)) {
      link::HostlessEvent m;
      m.event = static_cast<link::RunEvent>(e.code);
      m.position = e.position;
      m.trial_index = e.trial_index;
      m.device_time_us = e.time_us;
      if (e.code == RunEventCode::kImuFault)
        last_error_ = link::error_code_of(hostless_->imu_status());
      send(m);
    }
    TrialReport report;
    uint16_t trial_index = 0;
    if (hostless_->pop_result(trial_index, report.result)) {
      report.trial_id = trial_index;
      send_trial_result(report);
    }
  }

  void answer(const HostlessReply& r, link::MsgId id) {
    switch (r.refusal) {
      case HostlessRefusal::kNone:
        answer(Reply{}, id);
        return;
      case HostlessRefusal::kNoPlan:
        send_error(request_seq_, link::ErrorCode::kNoPlan, uint8_t(id));
        return;
      case HostlessRefusal::kBadPlan:
        send_error(request_seq_, link::ErrorCode::kBadPlan, r.detail);
        return;
      case HostlessRefusal::kCoreStatus:
        send_error(request_seq_, link::error_code_of(r.status), r.detail);
        return;
      case HostlessRefusal::kLogFull:
        send_error(request_seq_, link::ErrorCode::kLogFull, 0);
        return;
      case HostlessRefusal::kLogNotEmpty:
        send_error(request_seq_, link::ErrorCode::kLogNotEmpty, 0);
        return;
      case HostlessRefusal::kStorageFailed:
        send_error(request_seq_, link::ErrorCode::kStorageFailed, 0);
        return;
      case HostlessRefusal::kNoRecord:
        send_error(request_seq_, link::ErrorCode::kNoRecord, 0);
        return;
      case HostlessRefusal::kNotAllowed:
        send_error(request_seq_, link::ErrorCode::kNotAllowedInState, uint8_t(app_.state()));
        return;
    }
  }

  // Device -> host ids never reach here (the parser accepts host -> device only).
  template <class Msg>
  void on(const Msg&) {}

  // ---- replies
  void answer(const Reply& reply, link::MsgId id) {
    if (reply.ok()) {
      link::Ack a;
      a.request_seq = request_seq_;
      send(a);
    } else if (reply.refusal == Refusal::kNoScene) {
      send_error(request_seq_, link::ErrorCode::kNoScene, uint8_t(id));
    } else if (reply.refusal == Refusal::kNotAllowedInState) {
      send_error(request_seq_, link::ErrorCode::kNotAllowedInState, uint8_t(app_.state()));
    } else if (reply.refusal == Refusal::kTrialEnded) {
      send_error(request_seq_, link::error_code_of(reply.status), uint8_t(app_.state()));
    } else {
      send_error(request_seq_, link::error_code_of(reply.status), 0);
    }
  }

  // Every ERROR turns the motors off: a host whose request failed has lost track of what
  // the wearer feels, so nothing keeps vibrating on a stale command.
  void send_error(uint16_t seq, link::ErrorCode code, uint8_t detail) {
    all_motors_off();
    link::Error e;
    e.request_seq = seq;
    e.code = code;
    e.detail = detail;
    last_error_ = code;
    send(e);
  }

  // Off, and kept off: a host-less run would drive them again at its next tick (a pattern
  // plays on every poll), so an ERROR or a dropped frame during one ends the run, as STOP
  // does; the trial it was in has no record and runs again on the next HOSTLESS_RUN.
  void all_motors_off() {
    if (hostless_ && hostless_->running()) hostless_->stop();
    app_.motors_off();
  }

  template <class Msg>
  void send(const Msg& m) {
    uint8_t out[link::kMaxWireFrameSize];
    size_t n = 0;
    if (link::write_frame(m, seq_.next(), out, sizeof out, &n) == link::LinkStatus::kOk)
      stream_.write(out, n);
  }

  hal::ByteStream& stream_;
  Application& app_;
  DeviceInfo info_;
  PoseTimeListener* pose_time_;
  HostlessRunner* hostless_;
  link::FrameParser parser_{link::Accept::kHostToDevice};
  link::SequenceCounter seq_;
  uint16_t request_seq_ = 0;
  hal::LinkPoll link_poll_;
  link::ErrorCode last_error_ = link::ErrorCode::kOk;
};

}  // namespace graspguide::device
