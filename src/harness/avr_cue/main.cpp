// Cycle counts of the per-frame layer on the ATmega328P, under simavr at 8 MHz: the
// fixed-posture frame (error, alpha, PWM), the trial update and the watchdog decision, each
// on the inputs the host streams in, with the results printed for the host to check.
// Run by tools/graspguide/bench/avr_target.py through simavr_runner; the stream:
//   'S' mode:u8 k:u8 f_hat:f32[3] levels:f32[4]  a posture's PWM plan -> "S cycles"
//   'Q' wxyz:f32[4]           a frame from a quaternion -> "Q cycles status err alpha pwm0..3"
//   'G' gravity:f32[3]        a frame from gravity      -> the same, tagged "G"
//   'C' threshold hold timeout:f32 host_us now_us:u32  trial start -> "C cycles status"
//   'T' host_us:u32 error:f32         trial update       -> "T cycles status state"
//   'W' now_us:u32 pose:u8            watchdog decision  -> "W cycles expired passed"
//   'O'                               an empty count     -> "O cycles"
//   'E'                               the end            -> "E stack_bytes", and halts
// One line per record; err and alpha are the float's bits in hex, the rest is decimal.
#include "channel.h"
#include "graspguide_cue.h"

namespace gg = graspguide;

namespace {

constexpr uint32_t kStaleTimeoutUs = 200000;      // the device application's default
constexpr uint32_t kTrialClockSlackUs = 1000000;  // likewise

// The measured functions read and write these, never locals the compiler could compute
// outside the counted region.
struct Posture {
  gg::Mode mode = gg::Mode::kV;
  uint8_t k = 4;
  float f_hat[3] = {0, 0, -1};
  float levels[gg::kMaxContacts] = {0, 0, 0, 0};
  gg::PwmPlan<float> plan;
} g_posture;

struct FrameIn {
  float wxyz[4];
  float gravity[3];
} g_in;

struct FrameOut {
  gg::Status status;
  gg::Alignment<float> alignment;
  gg::Pwm pwm;
} g_out;

struct TrialIo {
  gg::TrialConfig config;
  uint32_t host_us = 0, now_us = 0;
  float error_deg = 0;
  gg::Status status = gg::Status::kOk;
  bool expired = false, passed = false;
} g_trial_io;

gg::Trial g_trial;
gg::HostTimeline g_timeline;
gg::TrialDeadline g_deadline;
gg::PoseWatchdog g_watchdog(kStaleTimeoutUs);

// Once per posture: which motors are on and their doubled levels.
__attribute__((noinline)) void plan_posture() {
  g_posture.plan = gg::plan_pwm(g_posture.levels, g_posture.k);
}

__attribute__((noinline)) void frame_from_quaternion() {
  g_out.status = gg::alignment_from_quaternion(g_in.wxyz, g_posture.f_hat, g_out.alignment);
  g_out.pwm =
      g_out.status == gg::Status::kOk
          ? gg::pwm_from_plan(g_posture.plan, gg::pwm_gain(g_posture.mode, g_out.alignment.alpha))
          : gg::Pwm{};
}

__attribute__((noinline)) void frame_from_gravity() {
  g_out.status = gg::alignment_from_gravity(g_in.gravity, g_posture.f_hat, g_out.alignment);
  g_out.pwm =
      g_out.status == gg::Status::kOk
          ? gg::pwm_from_plan(g_posture.plan, gg::pwm_gain(g_posture.mode, g_out.alignment.alpha))
          : gg::Pwm{};
}

__attribute__((noinline)) void trial_start() {
  g_trial_io.status = g_trial.start(g_trial_io.config, g_timeline.restart(g_trial_io.host_us));
  g_deadline.start(g_trial_io.now_us, g_trial_io.config.timeout_s, kTrialClockSlackUs);
}

__attribute__((noinline)) void trial_update() {
  g_trial_io.status =
      g_trial.update(g_timeline.advance(g_trial_io.host_us), double(g_trial_io.error_deg));
}

__attribute__((noinline)) void watchdog_decision() {
  g_trial_io.expired = g_watchdog.expired(g_trial_io.now_us);
  g_trial_io.passed = g_deadline.passed(g_trial_io.now_us);
}

__attribute__((noinline)) void nothing() {}

template <typename F>
void counted(F work) {
  channel::start_count();
  work();
  channel::stop_count();
}

void put_frame() {
  channel::put(' ');
  channel::put_uint(static_cast<uint8_t>(g_out.status));
  channel::put(' ');
  channel::put_float(g_out.alignment.error_deg);
  channel::put(' ');
  channel::put_float(g_out.alignment.alpha);
  for (uint8_t i = 0; i < gg::kMaxContacts; ++i) {
    channel::put(' ');
    channel::put_uint(g_out.pwm.duty[i]);
  }
}

}  // namespace

int main() {
  channel::paint();
  for (;;) {
    const char tag = static_cast<char>(channel::read_byte());
    switch (tag) {
      case 'S':
        g_posture.mode = static_cast<gg::Mode>(channel::read<uint8_t>());
        g_posture.k = channel::read<uint8_t>();
        channel::read_bytes(g_posture.f_hat, sizeof g_posture.f_hat);
        channel::read_bytes(g_posture.levels, sizeof g_posture.levels);
        channel::put("S ");
        counted(plan_posture);
        break;
      case 'Q':
        channel::read_bytes(g_in.wxyz, sizeof g_in.wxyz);
        channel::put("Q ");
        counted(frame_from_quaternion);
        put_frame();
        break;
      case 'G':
        channel::read_bytes(g_in.gravity, sizeof g_in.gravity);
        channel::put("G ");
        counted(frame_from_gravity);
        put_frame();
        break;
      case 'C':
        g_trial_io.config.threshold_deg = channel::read<float>();
        g_trial_io.config.hold_s = channel::read<float>();
        g_trial_io.config.timeout_s = channel::read<float>();
        g_trial_io.host_us = channel::read<uint32_t>();
        g_trial_io.now_us = channel::read<uint32_t>();
        channel::put("C ");
        counted(trial_start);
        channel::put(' ');
        channel::put_uint(static_cast<uint8_t>(g_trial_io.status));
        break;
      case 'T':
        g_trial_io.host_us = channel::read<uint32_t>();
        g_trial_io.error_deg = channel::read<float>();
        channel::put("T ");
        counted(trial_update);
        channel::put(' ');
        channel::put_uint(static_cast<uint8_t>(g_trial_io.status));
        channel::put(' ');
        channel::put_uint(static_cast<uint8_t>(g_trial.state()));
        break;
      case 'W':
        g_trial_io.now_us = channel::read<uint32_t>();
        if (channel::read<uint8_t>()) g_watchdog.feed(g_trial_io.now_us);
        channel::put("W ");
        counted(watchdog_decision);
        channel::put(' ');
        channel::put_uint(g_trial_io.expired);
        channel::put(' ');
        channel::put_uint(g_trial_io.passed);
        break;
      case 'O':
        channel::put("O ");
        counted(nothing);
        break;
      case 'E':
        channel::put("E ");
        channel::put_uint(channel::stack_used());
        channel::put('\n');
        channel::halt();
      default:  // the runner's 0xFF past the end of the input: it reports that
        channel::halt();
    }
    channel::put('\n');
  }
}
