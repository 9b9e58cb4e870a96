// The host-less wearable: a stored study plan run with no PC. Gravity comes from
// the IMU on the back of the hand, the posture is the plan's fixed one, a button starts each
// trial after a rest and a "ready" pattern, and each completed trial is appended to the
// results log in non-volatile storage before anything else happens.
//
// Per trial the per-posture work (Algorithm 1) runs once, when the rest before it begins;
// per sample the device only updates the gravity estimate and runs the per-frame layer.
// Board-independent: a board (or the simulated device) feeds it IMU samples, button edges
// and ticks; the link layer (link_device.h) uploads the plan and reads the log.
#pragma once

#include <cstring>

#include "graspguide.h"
#include "graspguide_cue/gravity_estimator.h"
#include "graspguide_cue/imu_watchdog.h"
#include "graspguide_device/plan_store.h"
#include "graspguide_device/results_log.h"
#include "graspguide_device/study_plan.h"
#include "graspguide_device/vibration_pattern.h"
#include "graspguide_hal/hal.h"

namespace graspguide::device {

// Why a host-less request was refused; the link maps each to its ErrorCode.
enum class HostlessRefusal : uint8_t {
  kNone = 0,
  kNoPlan,       // no plan begun (upload) or stored (run)
  kBadPlan,      // detail: the field (begin, trial) or the trial's position (commit)
  kCoreStatus,   // a trial the core cannot solve; status says why, detail its position
  kLogFull,      // no room for another record
  kLogNotEmpty,  // records of another plan are stored
  kStorageFailed,
  kNoRecord,
  kNotAllowed,  // a run goes on
};

struct HostlessReply {
  HostlessRefusal refusal = HostlessRefusal::kNone;
  Status status = Status::kOk;
  uint8_t detail = 0;
  bool ok() const { return refusal == HostlessRefusal::kNone; }
};

// The link's RunEvent values (static_assert in link_device.h).
enum class RunEventCode : uint8_t {
  kRest = 0,
  kReady,
  kTrialStarted,
  kSuccess,
  kTimeout,
  kPlanDone,
  kLogFull,
  kStorageFailed,
  kImuFault,
};

struct RunEvent {
  RunEventCode code = RunEventCode::kRest;
  uint16_t position = 0;
  uint16_t trial_index = 0;
  uint32_t time_us = 0;
};

// What one IMU sample did: the per-frame output the simulated device reports as TELEMETRY.
struct HostlessFrame {
  Real error_deg = 0;
  Real alpha = 0;
  Pwm pwm;  // what the motors show (guidance or a pattern)
  Status status = Status::kOk;
  bool trial_running = false;
};

enum class RunPhase : uint8_t { kOff = 0, kRest, kReadyPattern, kWaitButton, kTrial, kEndPattern };

class HostlessRunner {
 public:
  // output, accel_full_scale_mps2, gyro_full_scale_radps: what the board's Imu says of itself.
  HostlessRunner(hal::MotorOutputs& motors, hal::Clock& clock, NvStorage& store,
                 hal::ImuOutput output, float accel_full_scale_mps2, float gyro_full_scale_radps)
      : motors_(motors),
        clock_(clock),
        store_(store),
        log_(store),
        output_(output),
        imu_config_(make_imu_config(accel_full_scale_mps2, gyro_full_scale_radps)),
        imu_(imu_config_, clock.now_us()) {}

  // At power-up: the stored plan (if any) and the log. Returns the log's mount status;
  // plan_status() says why no plan was loaded (kOldLayout: upload the plan again).
  StoreStatus boot() {
    plan_status_ = load_plan(store_, plan_);
    plan_stored_ = plan_status_ == StoreStatus::kOk;
    if (plan_stored_) adopt_plan();
    return log_.mount();
  }

  // ---- plan upload (refused during a run)
  // The stored plan stays the device's plan until a commit replaces it: the upload's header
  // waits in its own copy, so plan_stored() and plan().header (LOG_INFO) go on describing
  // the stored plan, and an upload that is never committed hides nothing. The uploaded
  // trials go straight into the RAM plan (one StudyPlan in RAM, not two), so start() drops
  // an open upload and reloads the stored plan before it runs.
  HostlessReply begin_plan(const PlanHeader& header) {
    if (running()) return refuse(HostlessRefusal::kNotAllowed);
    HostlessReply r;
    if (check_header(header, &r.detail) != PlanCheck::kOk) return bad(r.detail);
    upload_header_ = header;
    uploading_ = true;
    received_ = 0;
    return HostlessReply{};
  }

  HostlessReply add_trial(uint16_t position, const PlanTrial& trial) {
    if (running()) return refuse(HostlessRefusal::kNotAllowed);
    if (!uploading_) return refuse(HostlessRefusal::kNoPlan);
    // In order, each once: a lost or repeated PLAN_TRIAL is the host's to resend.
    if (position != received_ || position >= upload_header_.trial_count) return bad(0);
    HostlessReply r;
    if (check_trial(trial, &r.detail) != PlanCheck::kOk) return bad(r.detail);
    plan_.trials[position] = trial;
    plan_id_valid_ = false;
    ++received_;
    return HostlessReply{};
  }

  HostlessReply commit_plan(uint16_t trial_count) {
    if (running()) return refuse(HostlessRefusal::kNotAllowed);
    if (!uploading_) return refuse(HostlessRefusal::kNoPlan);
    if (trial_count != upload_header_.trial_count || received_ != trial_count)
      return abandon(bad(uint8_t(received_ < 255 ? received_ : 255)));
    plan_.header = upload_header_;
    plan_id_valid_ = false;
    // Every trial solved once now, so a plan that cannot guide is refused at the desk, not
    // discovered by the wearer in trial 57.
    for (uint16_t i = 0; i < trial_count; ++i) {
      const Status s = prepare(plan_.trials[i]);
      if (s != Status::kOk) {
        HostlessReply r;
        r.refusal = HostlessRefusal::kCoreStatus;
        r.status = s;
        r.detail = uint8_t(i < 255 ? i : 255);
        return abandon(r);
      }
    }
    const uint32_t id = plan_id(plan_);
    if (log_.holds_other_plan(id)) return abandon(refuse(HostlessRefusal::kLogNotEmpty));
    if (save_plan(store_, plan_) != StoreStatus::kOk)
      return abandon(refuse(HostlessRefusal::kStorageFailed));
    uploading_ = false;
    plan_stored_ = true;
    plan_status_ = StoreStatus::kOk;
    adopt_plan();
    return HostlessReply{};
  }

  // ---- the run
  // From the first trial of the plan without a valid record, matched by trial_index (not
  // by counting records: a damaged record in the middle would shift every trial after it),
  // and each later trial without one; a trial with a record never runs again. A full log is
  // refused before anything moves. An open upload is dropped: the stored plan runs.
  HostlessReply start() {
    if (running()) return refuse(HostlessRefusal::kNotAllowed);
    if (uploading_) abandon(HostlessReply{});
    if (!plan_stored_) return refuse(HostlessRefusal::kNoPlan);
    if (!mark_recorded()) return refuse(HostlessRefusal::kStorageFailed);
    position_ = first_unrecorded(0);
    if (position_ >= plan_.header.trial_count) {
      emit(RunEventCode::kPlanDone);
      return HostlessReply{};
    }
    if (log_.full()) return refuse(HostlessRefusal::kLogFull);
    begin_rest(clock_.now_us());
    return HostlessReply{};
  }

  // Ends the run at once (STOP, a host taking over): motors off, an unfinished trial has
  // no record and runs again on the next start().
  void stop() {
    phase_ = RunPhase::kOff;
    patterns_.cancel();
    trial_.abort();
    motors_off();
  }

  // A debounced button edge (the board's Button, or the simulator's SIM_BUTTON).
  void on_button(bool pressed, uint32_t now_us) {
    if (!pressed || phase_ != RunPhase::kWaitButton) return;
    phase_ = RunPhase::kTrial;
    trial_started_us_ = now_us;
    trial_elapsed_us_ = 0;
    samples_ = 0;
    // A fault already holding the motors off counts for this trial too: its record must
    // not read as a clean one.
    faults_at_start_ = fault_total() - (imu_.motors_allowed() ? 0u : 1u);
    trial_.start(guidance_.scene().trial, 0);
    emit(RunEventCode::kTrialStarted);
  }

  // One IMU sample, in the IMU's axes, stamped with the device's clock. A sample stamped
  // before the last one (signed 32-bit difference) is refused: see time_went_backwards().
  HostlessFrame on_sample(const hal::ImuSample& s) {
    if (have_sample_ && int32_t(s.time_us - last_sample_us_) < 0) return time_went_backwards(s);
    HostlessFrame out;
    const Real accel[3] = {Real(s.accel_mps2[0]), Real(s.accel_mps2[1]), Real(s.accel_mps2[2])};
    const Real gyro[3] = {Real(s.gyro_radps[0]), Real(s.gyro_radps[1]), Real(s.gyro_radps[2])};
    const bool was_allowed = imu_.motors_allowed();
    const Status health = imu_.on_sample(accel, gyro, s.time_us);
    // Any fault's onset in a trial is news (stale is found by tick(), below).
    if (was_allowed && health != Status::kOk && phase_ == RunPhase::kTrial)
      emit(RunEventCode::kImuFault);
    if (health == Status::kOk) estimate(accel, gyro, s.time_us);
    last_sample_us_ = s.time_us;
    have_sample_ = true;
    out.status = health;
    if (phase_ == RunPhase::kTrial) {
      ++samples_;
      guide(s.time_us, health, out);
    }
    tick(s.time_us);
    out.pwm = shown_;
    out.trial_running = phase_ == RunPhase::kTrial;
    return out;
  }

  // Call every control loop: the IMU's stale rule, the rest and pattern timers, and a
  // trial's timeout when samples stopped coming.
  void tick(uint32_t now_us) {
    const bool was_allowed = imu_.motors_allowed();
    imu_.poll(now_us);
    if (was_allowed && !imu_.motors_allowed() && phase_ == RunPhase::kTrial) {
      motors_off();
      emit(RunEventCode::kImuFault);
    }
    switch (phase_) {
      // Elapsed phase time is a signed difference: a "now" from before the phase began
      // (read just before a sample stamped later) is no time, never 2^32 us.
      case RunPhase::kRest:
        if (int32_t(now_us - phase_start_us_) < int32_t(rest_us_)) break;
        // The pattern begins in this tick, so what a sample reports is what the motors show.
        start_pattern(RunPhase::kReadyPattern, kReadyPattern, now_us);
        [[fallthrough]];
      case RunPhase::kReadyPattern:
      case RunPhase::kEndPattern:
        if (int32_t(now_us - phase_start_us_) < 0) break;
        show(patterns_.pwm(now_us));
        if (!patterns_.playing(now_us)) {
          if (phase_ == RunPhase::kReadyPattern) {
            phase_ = RunPhase::kWaitButton;
            emit(RunEventCode::kReady);
          } else {
            next_trial(now_us);
          }
        }
        break;
      case RunPhase::kTrial:
        // The trial's time is the device's, whether or not samples arrive: a dead IMU
        // still ends the trial at its timeout (as a failure, motors already off).
        advance_trial_clock(now_us);
        if (trial_elapsed_us_ >= uint64_t(guidance_.scene().trial.timeout_s * 1e6)) {
          trial_.expire();
          finish_trial(now_us);
        }
        break;
      default:
        break;
    }
  }

  bool pop_event(RunEvent& out) {
    if (events_count_ == 0) return false;
    out = events_[events_head_];
    events_head_ = uint8_t((events_head_ + 1) % kEventSlots);
    --events_count_;
    return true;
  }

  // The TRIAL_RESULT of the trial that just ended, once.
  bool pop_result(uint16_t& trial_index, TrialResult& result) {
    if (!result_pending_) return false;
    result_pending_ = false;
    trial_index = last_trial_index_;
    result = last_result_;
    return true;
  }

  bool running() const { return phase_ != RunPhase::kOff; }
  RunPhase phase() const { return phase_; }
  bool plan_stored() const { return plan_stored_; }
  // What the last load of the stored plan found: kOldLayout is a plan of an older firmware,
  // refused (never misread) until the host uploads it again.
  StoreStatus plan_status() const { return plan_status_; }
  const StudyPlan& plan() const { return plan_; }
  ResultsLog& log() { return log_; }
  const ImuFaultCounts& imu_faults() const { return imu_.faults(); }
  Status imu_status() const { return imu_.status(); }
  uint16_t position() const { return position_; }

 private:
  static constexpr uint8_t kEventSlots = 8;

  static ImuWatchdogConfig<Real> make_imu_config(float accel_fs, float gyro_fs) {
    ImuWatchdogConfig<Real> c;
    c.accel_full_scale_mps2 = Real(accel_fs);
    c.gyro_full_scale_radps = Real(gyro_fs);
    return c;
  }

  const PlanTrial& current() const { return plan_.trials[position_]; }

  // Which plan positions hold a valid record of this plan: each record marks the first
  // unmarked position with its trial_index. False when the log cannot be read.
  bool mark_recorded() {
    std::memset(recorded_, 0, sizeof recorded_);
    const uint32_t id = plan_id_of_plan();
    const uint16_t n = plan_.header.trial_count;
    for (uint16_t i = 0; i < log_.records(); ++i) {
      LogRecord rec;
      uint32_t rec_id = 0;
      if (log_.read(i, rec, &rec_id) != StoreStatus::kOk) return false;
      if (rec_id != id) continue;
      for (uint16_t p = 0; p < n; ++p)
        if (!is_recorded(p) && plan_.trials[p].trial_index == rec.trial.trial_index) {
          set_recorded(p);
          break;
        }
    }
    return true;
  }

  bool is_recorded(uint16_t p) const { return (recorded_[p / 8] >> (p % 8)) & 1u; }
  void set_recorded(uint16_t p) { recorded_[p / 8] = uint8_t(recorded_[p / 8] | (1u << (p % 8))); }

  // The first position at or after from without a record (trial_count: none is left).
  uint16_t first_unrecorded(uint16_t from) const {
    const uint16_t n = plan_.header.trial_count;
    while (from < n && is_recorded(from)) ++from;
    return from;
  }

  // A sample stamped before the last one: the device's clock cannot time this phase any
  // more. The sample is not used (status time_went_backwards, motors off) and time counts
  // on from its stamp, so a clock that really restarted costs one sample, not the run. A
  // trial under way is aborted with no record and no result, and begins again with its rest
  // (as the tracker path ends a trial whose POSE steps back); a rest or a pattern starts
  // over from this stamp. No duration is ever made from the step.
  HostlessFrame time_went_backwards(const hal::ImuSample& s) {
    HostlessFrame out;
    out.status = Status::kTimeWentBackwards;
    last_sample_us_ = s.time_us;
    motors_off();
    switch (phase_) {
      case RunPhase::kTrial:
        trial_.abort();
        begin_rest(s.time_us);
        break;
      case RunPhase::kRest:
        phase_start_us_ = s.time_us;
        break;
      case RunPhase::kReadyPattern:
        start_pattern(RunPhase::kReadyPattern, kReadyPattern, s.time_us);
        break;
      case RunPhase::kEndPattern:
        start_pattern(RunPhase::kEndPattern,
                      last_result_.success ? kSuccessPattern : kTimeoutPattern, s.time_us);
        break;
      default:
        break;
    }
    out.pwm = shown_;
    out.trial_running = false;
    return out;
  }

  void start_pattern(RunPhase phase, const VibrationPattern& p, uint32_t now_us) {
    phase_ = phase;
    phase_start_us_ = now_us;
    patterns_.start(p, current().k, now_us);
  }

  // The plan's fixed mounting, as a rotation matrix from IMU axes to hand axes (the
  // quaternion was checked to be finite with a norm in [0.5, 2]).
  void adopt_plan() {
    plan_id_valid_ = false;
    const float* q = plan_.header.imu_to_hand_wxyz;
    const Real n = scalar_math::sqrt_of(Real(q[0]) * q[0] + Real(q[1]) * q[1] + Real(q[2]) * q[2] +
                                        Real(q[3]) * q[3]);
    const Real w = q[0] / n, x = q[1] / n, y = q[2] / n, z = q[3] / n;
    const Real r[3][3] = {
        {1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)},
        {2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)},
        {2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)},
    };
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) imu_to_hand_[i][j] = r[i][j];
  }

  // The scene and wrench of one planned trial, solved once (Algorithm 1's per-posture part).
  Status prepare(const PlanTrial& t) {
    const PlanHeader& h = plan_.header;
    Scene<Real> scene;
    scene.k = t.k;
    scene.contacts.setZero();
    for (int i = 0; i < t.k; ++i)
      for (int j = 0; j < 3; ++j)
        scene.contacts(j, i) = Real(t.k == 3 ? h.hand_k3[i][j] : h.hand_k4[i][j]);
    scene.y_axis = Vec3<Real>(h.y_axis[0], h.y_axis[1], h.y_axis[2]);
    scene.constraints = static_cast<ConstraintModel>(h.constraints);
    scene.policy = static_cast<Policy>(t.policy);
    scene.mode = static_cast<Mode>(t.mode);
    scene.trial.threshold_deg = h.threshold_deg;
    scene.trial.hold_s = h.hold_s;
    scene.trial.timeout_s = h.timeout_s;
    // The participant's calibration shapes every trial's PWM (the patterns stay at their
    // fixed duty: they are told apart by rhythm). Checked with the plan's header.
    guidance_.set_calibration(plan_calibration(h));
    Vec6<Real> w;
    for (int j = 0; j < 6; ++j) w(j) = Real(t.wrench[j]);
    Status s = geometry_status<Real>(scene);
    if (s == Status::kOk) s = guidance_.set_scene(scene);
    if (s == Status::kOk) s = guidance_.set_wrench(w);
    if (s != Status::kOk) return s;
    const Real down[3] = {0, 0, -1};
    FrameResult<Real> probe;
    s = guidance_.update_gravity(down, probe);
    return s;
  }

  void begin_rest(uint32_t now_us) {
    phase_ = RunPhase::kRest;
    phase_start_us_ = now_us;
    rest_us_ = uint32_t(plan_.header.rest_s * 1e6f);
    motors_off();
    const Status s = prepare(current());
    if (s != Status::kOk) {  // checked at commit; only a corrupted RAM copy gets here
      stop();
      emit(RunEventCode::kStorageFailed);
      return;
    }
    emit(RunEventCode::kRest);
  }

  void estimate(const Real accel[3], const Real gyro[3], uint32_t time_us) {
    if (output_ == hal::ImuOutput::kFusedGravity) {
      // The chip's gravity points up like the accelerometer; set_fused flips it.
      estimator_.set_fused(accel);
      return;
    }
    const Real dt_s = Real(time_us - last_sample_us_) * Real(1e-6);
    // After a gap (or the first sample) the filter restarts from the accelerometer: a
    // first-order step over a long gap would be wrong, and the gap's motion is unknown.
    if (!have_sample_ || !(dt_s > Real(0)) || dt_s > Real(kMaxSampleInterval_s)) {
      estimator_.reset();
      estimator_.update(accel, gyro, Real(0.01));
      return;
    }
    estimator_.update(accel, gyro, dt_s);
  }

  // The trial's time is the device's clock since the press, across its 32-bit wrap, in
  // steps read as signed differences: a "now" before the last one adds nothing (and is not
  // kept), so no step back ever reads as 2^32 us.
  void advance_trial_clock(uint32_t now_us) {
    const int32_t step = int32_t(now_us - trial_started_us_);
    if (step <= 0) return;
    trial_elapsed_us_ += uint32_t(step);
    trial_started_us_ = now_us;
  }

  void guide(uint32_t now_us, Status health, HostlessFrame& out) {
    advance_trial_clock(now_us);
    if (health != Status::kOk || !estimator_.initialised()) {
      motors_off();
      out.status = health != Status::kOk ? health : Status::kImuStale;
      return;
    }
    const Real* g_imu = estimator_.gravity();
    Real g_hand[3];
    for (int i = 0; i < 3; ++i)
      g_hand[i] = imu_to_hand_[i][0] * g_imu[0] + imu_to_hand_[i][1] * g_imu[1] +
                  imu_to_hand_[i][2] * g_imu[2];
    FrameResult<Real> frame;
    const Status s = guidance_.update_gravity(g_hand, frame);
    out.status = s;
    if (s != Status::kOk) {
      motors_off();
      return;
    }
    out.error_deg = frame.error_deg;
    out.alpha = frame.alpha;
    trial_.update(int64_t(trial_elapsed_us_), double(frame.error_deg));
    if (!trial_.running()) {
      finish_trial(now_us);
      return;
    }
    show(frame.pwm);
  }

  // The record first: once it is durable the wearer is told, and only then does the next
  // trial begin; a power cut anywhere before loses this trial only, which runs again.
  void finish_trial(uint32_t now_us) {
    motors_off();
    const PlanTrial& t = current();
    LogRecord rec;
    rec.trial = t;
    rec.success = trial_.result().success;
    rec.completion_s = float(trial_.result().completion_s);
    rec.first_entry_s = float(trial_.result().first_entry_s);
    rec.final_error_deg = float(trial_.result().final_error_deg);
    rec.samples = samples_;
    const uint32_t faults = fault_total() - faults_at_start_;
    rec.imu_faults = uint16_t(faults > 0xFFFF ? 0xFFFF : faults);
    const StoreStatus s = log_.append(rec, plan_id_of_plan());
    if (s != StoreStatus::kOk) {
      stop();
      emit(s == StoreStatus::kFull ? RunEventCode::kLogFull : RunEventCode::kStorageFailed);
      return;
    }
    set_recorded(position_);
    last_trial_index_ = t.trial_index;
    last_result_ = trial_.result();
    result_pending_ = true;
    emit(rec.success ? RunEventCode::kSuccess : RunEventCode::kTimeout);
    start_pattern(RunPhase::kEndPattern, rec.success ? kSuccessPattern : kTimeoutPattern, now_us);
  }

  void next_trial(uint32_t now_us) {
    position_ = first_unrecorded(uint16_t(position_ + 1));
    if (position_ >= plan_.header.trial_count) {
      phase_ = RunPhase::kOff;
      motors_off();
      emit(RunEventCode::kPlanDone);
      return;
    }
    if (log_.full()) {
      stop();
      emit(RunEventCode::kLogFull);
      return;
    }
    begin_rest(now_us);
  }

  uint32_t plan_id_of_plan() {
    if (!plan_id_valid_) {
      plan_id_cache_ = plan_id(plan_);
      plan_id_valid_ = true;
    }
    return plan_id_cache_;
  }

  uint32_t fault_total() const {
    const ImuFaultCounts& f = imu_.faults();
    return f.stale + f.stuck + f.out_of_range;
  }

  void emit(RunEventCode code) {
    RunEvent e;
    e.code = code;
    const uint16_t n = plan_.header.trial_count;
    e.position = position_ < n ? position_ : uint16_t(n ? n - 1 : 0);
    e.trial_index = n ? plan_.trials[e.position].trial_index : 0;
    e.time_us = clock_.now_us();
    if (events_count_ == kEventSlots) {  // the oldest is dropped: nobody is listening
      events_head_ = uint8_t((events_head_ + 1) % kEventSlots);
      --events_count_;
    }
    events_[(events_head_ + events_count_) % kEventSlots] = e;
    ++events_count_;
  }

  void show(const Pwm& pwm) {
    motors_.write(pwm);
    shown_ = pwm;
  }

  void motors_off() { show(Pwm{}); }

  HostlessReply refuse(HostlessRefusal why) {
    HostlessReply r;
    r.refusal = why;
    return r;
  }

  HostlessReply bad(uint8_t detail) {
    HostlessReply r;
    r.refusal = HostlessRefusal::kBadPlan;
    r.detail = detail;
    return r;
  }

  // A failed commit leaves the stored plan as it was, and in RAM too.
  HostlessReply abandon(HostlessReply r) {
    uploading_ = false;
    plan_id_valid_ = false;
    plan_status_ = load_plan(store_, plan_);
    plan_stored_ = plan_status_ == StoreStatus::kOk;
    if (plan_stored_) adopt_plan();
    return r;
  }

  hal::MotorOutputs& motors_;
  hal::Clock& clock_;
  NvStorage& store_;
  ResultsLog log_;
  hal::ImuOutput output_;
  ImuWatchdogConfig<Real> imu_config_;
  ImuWatchdog<Real> imu_;
  GravityEstimator<Real> estimator_;
  Guidance<Real> guidance_;
  Trial trial_;
  PatternPlayer patterns_;
  StudyPlan plan_;
  PlanHeader upload_header_;  // the open upload's; plan_.header stays the stored plan's
  uint8_t recorded_[(kMaxPlanTrials + 7) / 8] = {};  // by plan position: a valid record
  Real imu_to_hand_[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  Pwm shown_;
  RunEvent events_[kEventSlots];
  uint8_t events_head_ = 0, events_count_ = 0;
  RunPhase phase_ = RunPhase::kOff;
  uint16_t position_ = 0, received_ = 0, last_trial_index_ = 0;
  uint32_t phase_start_us_ = 0, rest_us_ = 0, trial_started_us_ = 0, last_sample_us_ = 0;
  uint32_t samples_ = 0, faults_at_start_ = 0, plan_id_cache_ = 0;
  uint64_t trial_elapsed_us_ = 0;
  TrialResult last_result_;
  StoreStatus plan_status_ = StoreStatus::kNoPlan;
  bool plan_stored_ = false, uploading_ = false, have_sample_ = false;
  bool result_pending_ = false, plan_id_valid_ = false;
};

}  // namespace graspguide::device
