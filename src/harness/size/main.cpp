// GraspGuide: bare-metal harness for a generic Cortex-M4F. It runs the real device
// application (graspguide::device::Application over the core) on trivial hardware: a
// register-like PWM sink and a SysTick clock, no vendor headers. For each of 3 and 4
// contacts it sets a scene, starts a trial and feeds poses that turn the hand into
// alignment, so the linker keeps what a board would run (the QR route only, as shipped).
// The results are left in volatile words for a debugger or QEMU (mps2-an386).
#include <cstdint>

#include "cortex_m_hal.h"
#include "graspguide.h"
#include "graspguide_device/application.h"

using graspguide::Real;
namespace gg = graspguide;
namespace dev = graspguide::device;

extern "C" {
// What the harness saw, for a debugger or a QEMU test.
volatile uint32_t m4f_trials_ok;    // trials that succeeded (2 expected)
volatile uint32_t m4f_poses_ok;     // poses the application accepted
volatile uint32_t m4f_last_status;  // first non-ok Status or Refusal seen (0: none)
volatile float m4f_last_error_deg;
volatile uint32_t m4f_max_compute_us;  // slowest Guidance::update
volatile uint32_t m4f_stack_peak;      // bytes of stack ever used (painted by start-up)
// Inputs read through volatile, so the compiler cannot fold the scenes into constants.
volatile float m4f_scale = 1.0f;
uint32_t m4f_stack_high_water(void);  // startup.c
}

namespace {

gg::m4f::SysTickClock g_clock;
gg::m4f::RegisterMotors g_motors;
// Dynamic initialisation (its constructor writes the motors off): runs from .init_array.
dev::Application g_app(g_motors, g_clock);

using Vec4 = Eigen::Matrix<Real, 4, 1>;

// q * r for [w x y z] quaternions.
Vec4 quat_mul(const Vec4& q, const Vec4& r) {
  Vec4 p;
  p << q[0] * r[0] - q[1] * r[1] - q[2] * r[2] - q[3] * r[3],
      q[0] * r[1] + q[1] * r[0] + q[2] * r[3] - q[3] * r[2],
      q[0] * r[2] - q[1] * r[3] + q[2] * r[0] + q[3] * r[1],
      q[0] * r[3] + q[1] * r[2] - q[2] * r[1] + q[3] * r[0];
  return p;
}

void note(const dev::Reply& r) {
  if (!r.ok() && m4f_last_status == 0)
    m4f_last_status =
        r.status != gg::Status::kOk ? 0x100u + uint32_t(r.status) : 0x200u + uint32_t(r.refusal);
}

// One trial; true if it succeeded.
bool run_trial(uint16_t id, int k, gg::Decomposition route) {
  const Real s = m4f_scale;
  // The README's example grasp (thumb, index, middle), plus the palm for k = 4.
  gg::Scene<Real> scene;
  scene.k = k;
  scene.contacts.col(0) << s * Real(0.045), s * Real(0.045), s * Real(0.035);
  scene.contacts.col(1) << s * Real(0.015), s * Real(0.095), s * Real(0.040);
  scene.contacts.col(2) << s * Real(-0.010), s * Real(0.100), s * Real(0.040);
  scene.contacts.col(3) << s * Real(0.020), s * Real(0.030), s * Real(-0.010);
  scene.policy = k == 3 ? gg::Policy::kF : gg::Policy::kFperp;
  scene.mode = k == 3 ? gg::Mode::kV : gg::Mode::kC;
  scene.solver.decomposition = route;
  dev::Reply r = g_app.set_scene(scene);
  note(r);
  if (!r.ok()) return false;

  gg::Vec6<Real> wrench;
  wrench << s * Real(0.4), s * Real(-1), s * Real(0.3), 0, 0, 0;
  r = g_app.start_trial(id, wrench);
  note(r);
  if (!r.ok()) return false;

  // Start 60 degrees off the aligned pose (R f_hat = g), turn back 1 degree per 10 ms
  // frame about a hand axis perpendicular to f_hat, then hold: success after about
  // 1.1 s of host time. Precomputed [w x y z] quaternions (no sinf/cosf needed).
  Vec4 q(Real(0.48131776), Real(0.78196881), Real(-0.0110707), Real(0.39589825));
  const Vec4 step(Real(0.99996192), 0, Real(-0.00250755), Real(-0.00835851));
  dev::PoseIn in;
  dev::Telemetry tel;
  dev::TrialReport report;
  bool ended = false;
  for (uint32_t i = 0; i < 200 && !ended; ++i) {
    in.host_time_us = i * 10000u;
    in.quat_wxyz = q;
    r = g_app.pose(in, tel, report, ended);
    note(r);
    if (r.ok()) m4f_poses_ok = m4f_poses_ok + 1;
    m4f_last_error_deg = tel.error_deg;
    if (tel.compute_time_us > m4f_max_compute_us) m4f_max_compute_us = tel.compute_time_us;
    g_app.tick();
    if (i < 60) q = quat_mul(q, step);
  }
  return ended && report.result.success && report.trial_id == id;
}

}  // namespace

int main() {
  g_clock.start();
  uint16_t id = 0;
  for (int k = gg::kMinContacts; k <= gg::kMaxContacts; ++k)
    if (run_trial(++id, k, gg::Decomposition::kStructured)) m4f_trials_ok = m4f_trials_ok + 1;
  g_app.stop();
  m4f_stack_peak = m4f_stack_high_water();
  return m4f_trials_ok == id ? 0 : 1;
}
