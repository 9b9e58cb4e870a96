// The wearable controller's application, independent of any board: scene, trial,
// pose-driven guidance, watchdog and motor output. The protocol layer turns frames into
// these calls; a board provides the MotorOutputs and Clock.
#pragma once

#include "graspguide.h"
#include "graspguide_cue/trial_clock.h"
#include "graspguide_cue/watchdog.h"
#include "graspguide_hal/hal.h"

#ifndef GRASPGUIDE_STALE_TIMEOUT_MS
#define GRASPGUIDE_STALE_TIMEOUT_MS 200  // no POSE for this long: motors off
#endif
#ifndef GRASPGUIDE_TRIAL_CLOCK_SLACK_MS
// How far the device's own clock may run past timeout_s before it ends a trial whose pose
// timestamps stopped advancing. Host and device clocks agree far better than this; the
// slack only keeps the host's timeline the one that normally decides.
#define GRASPGUIDE_TRIAL_CLOCK_SLACK_MS 1000
#endif

namespace graspguide::device {

inline constexpr uint32_t kDefaultStaleTimeoutUs = uint32_t(GRASPGUIDE_STALE_TIMEOUT_MS) * 1000u;
inline constexpr uint32_t kTrialClockSlackUs = uint32_t(GRASPGUIDE_TRIAL_CLOCK_SLACK_MS) * 1000u;

enum class DeviceState : uint8_t { kIdle = 0, kSceneSet = 1, kTrialRunning = 2, kStopped = 3 };

// Why a request was refused without reaching the core. kTrialEnded: a POSE whose timestamp
// could not follow the trial's ended that trial (Reply::status says why).
enum class Refusal : uint8_t { kNone = 0, kNotAllowedInState, kNoScene, kTrialEnded };

struct Reply {
  Status status = Status::kOk;
  Refusal refusal = Refusal::kNone;
  bool ok() const { return status == Status::kOk && refusal == Refusal::kNone; }
};

struct PoseIn {
  uint32_t host_time_us = 0;
  Eigen::Matrix<Real, 4, 1> quat_wxyz = Eigen::Matrix<Real, 4, 1>(1, 0, 0, 0);
  bool has_contacts = false;
  Eigen::Matrix<Real, 3, kMaxContacts> contacts = Eigen::Matrix<Real, 3, kMaxContacts>::Zero();
};

struct Telemetry {
  uint32_t host_time_us = 0;
  Real error_deg = 0;
  Real alpha = 0;
  Pwm pwm;  // what the motors were set to
  ConstraintModel used = ConstraintModel::kNone;
  Status status = Status::kOk;
  uint8_t iterations = 0;
  bool recomputed = false;
  bool trial_running = false;
  uint32_t compute_time_us = 0;
};

struct TrialReport {
  uint16_t trial_id = 0;
  TrialResult result;
};

struct Counters {
  uint32_t poses = 0;
  uint32_t stale_events = 0;
  uint32_t refused = 0;
  uint32_t trials_ended_by_device_clock = 0;
};

class Application {
 public:
  Application(hal::MotorOutputs& motors, hal::Clock& clock,
              uint32_t stale_timeout_us = kDefaultStaleTimeoutUs)
      : motors_(motors), clock_(clock), watchdog_(stale_timeout_us) {
    motors_off();  // whatever the pins did before boot
  }

  // A new scene; refused while a trial runs. An invalid one is reported and the previous
  // valid scene stays.
  // *bad_field, when given, names the trial field behind a kBadConfig.
  Reply set_scene(const Scene<Real>& scene, TrialField* bad_field = nullptr) {
    if (state_ == DeviceState::kTrialRunning) return refuse(Refusal::kNotAllowedInState);
    if (validate_trial_config(scene.trial, bad_field) != Status::kOk)
      return fail(Status::kBadConfig);
    Status s = geometry_status<Real>(scene);
    if (s == Status::kOk) s = guidance_.set_scene(scene);
    if (s != Status::kOk) return fail(s);
    good_contacts_ = scene.contacts;
    state_ = DeviceState::kSceneSet;
    return Reply{};
  }

  Reply start_trial(uint16_t trial_id, const Vec6<Real>& wrench) {
    if (state_ == DeviceState::kIdle) return refuse(Refusal::kNoScene);
    if (state_ == DeviceState::kTrialRunning) return refuse(Refusal::kNotAllowedInState);
    // Solving the grasp now reports a bad wrench at once, and the first pose then finds the
    // grasp part already computed (the posture has not changed).
    FrameResult<Real> probe;
    Status s = guidance_.set_wrench(wrench);
    if (s == Status::kOk) s = guidance_.update(Eigen::Matrix<Real, 4, 1>(1, 0, 0, 0), probe);
    if (s != Status::kOk) return fail(s);
    trial_id_ = trial_id;
    trial_started_ = false;  // the trial's clock starts with its first pose
    state_ = DeviceState::kTrialRunning;
    return Reply{};
  }

  // One tracker frame. Fills the telemetry; fills report and sets *ended when the trial
  // ends with this pose.
  Reply pose(const PoseIn& in, Telemetry& out, TrialReport& report, bool& ended) {
    ended = false;
    out = Telemetry{};
    out.host_time_us = in.host_time_us;
    if (state_ == DeviceState::kIdle) return refuse(Refusal::kNoScene);
    ++counters_.poses;
    watchdog_.feed(clock_.now_us());
    stale_ = false;
    if (state_ != DeviceState::kTrialRunning) {
      motors_off();
      return refuse(Refusal::kNotAllowedInState);  // no wrench to render outside a trial
    }
    // The trial's clocks start with its first POSE, even one that fails below: a trial must
    // end on the device's clock whatever its POSEs carry.
    const int64_t t_us =
        trial_started_ ? timeline_.advance(in.host_time_us) : timeline_.restart(in.host_time_us);
    if (!trial_started_) {
      trial_.start(guidance_.scene().trial, t_us);
      trial_started_ = true;
      deadline_.start(clock_.now_us(), guidance_.scene().trial.timeout_s, kTrialClockSlackUs);
    } else if (t_us < trial_last_us_) {
      // A step back, or one forward of 2^31 us or more (the same thing on a 32-bit
      // timestamp): the host's timeline can no longer be trusted to end the trial, so it
      // ends here, like STOP, and the POSE is answered with an ERROR that says why.
      abort_trial();
      Reply reply = fail(Status::kTimeWentBackwards);
      reply.refusal = Refusal::kTrialEnded;
      return reply;
    }
    trial_last_us_ = t_us;
    if (in.has_contacts) {
      const Status s = guidance_.set_contacts(in.contacts);
      if (s != Status::kOk) return fail(s, &out);
    }
    const uint32_t t0 = clock_.now_us();
    FrameResult<Real> frame;
    const Status s = guidance_.update(in.quat_wxyz, frame);
    out.compute_time_us = clock_.now_us() - t0;
    out.recomputed = frame.recomputed;
    out.iterations = static_cast<uint8_t>(
        guidance_.grasp().iterations > 255 ? 255 : guidance_.grasp().iterations);
    if (s != Status::kOk) {
      // Back to the last contacts that worked, so the next pose without contacts renders.
      if (in.has_contacts) guidance_.set_contacts(good_contacts_);
      return fail(s, &out);
    }
    if (in.has_contacts) good_contacts_ = in.contacts;
    out.error_deg = frame.error_deg;
    out.alpha = frame.alpha;
    out.used = guidance_.grasp().used;

    const Status ts = trial_.update(t_us, double(frame.error_deg));
    if (ts != Status::kOk) return fail(ts, &out);
    if (!trial_.running()) {
      motors_off();
      state_ = DeviceState::kSceneSet;
      report.trial_id = trial_id_;
      report.result = trial_.result();
      ended = true;
      out.pwm = Pwm{};
      return Reply{};
    }
    motors_.write(frame.pwm);
    motors_on_ = !all_zero(frame.pwm);
    out.pwm = frame.pwm;
    out.trial_running = true;
    return Reply{};
  }

  // The participant's per-motor PWM floor and gain, for every following POSE (SET_MOTORS
  // stays raw: calibration measures with it). Refused while a trial runs, so a trial is
  // rendered with one mapping; an invalid one is refused and the previous one stays.
  // *bad_field, when given, names the field behind a kBadConfig.
  Reply set_calibration(const MotorCalibration& calibration,
                        CalibrationField* bad_field = nullptr) {
    if (state_ == DeviceState::kTrialRunning) return refuse(Refusal::kNotAllowedInState);
    const CalibrationCheck c = check_calibration(calibration);
    if (c != CalibrationCheck::kOk) {
      if (bad_field) *bad_field = calibration_field(c);
      return fail(Status::kBadConfig);
    }
    guidance_.set_calibration(calibration);
    return Reply{};
  }

  const MotorCalibration& calibration() const { return guidance_.calibration(); }

  // Acts at once, whatever the state.
  void stop() {
    motors_off();
    abort_trial();
  }

  // Every ERROR the link sends, and every frame it drops, turns the motors off (safe by
  // default); a running trial goes on and the next good POSE drives them again.
  void motors_off() {
    motors_.write(Pwm{});
    motors_on_ = false;
  }

  // Direct PWM for calibration; the watchdog still switches it off without poses.
  Reply set_motors(const Pwm& pwm) {
    if (state_ == DeviceState::kTrialRunning) return refuse(Refusal::kNotAllowedInState);
    motors_.write(pwm);
    motors_on_ = !all_zero(pwm);
    watchdog_.feed(clock_.now_us());
    return Reply{};
  }

  // Call as often as possible: switches the motors off when poses stop coming, and ends a
  // trial that the device's own clock has seen outlast its timeout (poses whose timestamps
  // froze would otherwise keep it running forever). Returns true, with *report filled,
  // when a trial ended here: a failure at timeout_s, as every timed-out trial.
  bool tick(TrialReport* report = nullptr) {
    if (motors_on_ && watchdog_.expired(clock_.now_us())) {
      motors_off();
      if (!stale_) ++counters_.stale_events;
      stale_ = true;
    }
    if (state_ != DeviceState::kTrialRunning || !trial_started_) return false;
    if (!deadline_.passed(clock_.now_us())) return false;
    trial_.expire();
    motors_off();
    state_ = DeviceState::kSceneSet;
    ++counters_.trials_ended_by_device_clock;
    if (report) {
      report->trial_id = trial_id_;
      report->result = trial_.result();
    }
    return true;
  }

  uint32_t now_us() { return clock_.now_us(); }
  hal::Clock& clock() { return clock_; }

  DeviceState state() const { return state_; }
  const Counters& counters() const { return counters_; }
  Status last_error() const { return last_error_; }
  bool motors_on() const { return motors_on_; }

 private:
  static bool all_zero(const Pwm& p) {
    for (uint8_t d : p.duty)
      if (d != 0) return false;
    return true;
  }

  void abort_trial() {
    trial_.abort();
    if (state_ != DeviceState::kIdle) state_ = DeviceState::kStopped;
  }

  Reply refuse(Refusal r) {
    ++counters_.refused;
    Reply reply;
    reply.refusal = r;
    return reply;
  }

  Reply fail(Status s, Telemetry* out = nullptr) {
    motors_off();
    last_error_ = s;
    if (out) {
      out->status = s;
      out->pwm = Pwm{};
      // A failed POSE does not end the trial; a host reading a cleared flag would wait
      // for a TRIAL_RESULT that never comes.
      out->trial_running = state_ == DeviceState::kTrialRunning;
    }
    Reply reply;
    reply.status = s;
    return reply;
  }

  hal::MotorOutputs& motors_;
  hal::Clock& clock_;
  PoseWatchdog watchdog_;
  Guidance<Real> guidance_;
  Trial trial_;
  DeviceState state_ = DeviceState::kIdle;
  Counters counters_;
  Status last_error_ = Status::kOk;
  Eigen::Matrix<Real, 3, kMaxContacts> good_contacts_ =
      Eigen::Matrix<Real, 3, kMaxContacts>::Zero();
  uint16_t trial_id_ = 0;
  bool trial_started_ = false;
  bool motors_on_ = false;
  bool stale_ = false;
  HostTimeline timeline_;
  TrialDeadline deadline_;  // the device's clock since the trial's first POSE
  int64_t trial_last_us_ = 0;
};

}  // namespace graspguide::device
