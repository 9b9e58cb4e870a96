// Instruction counts of Algorithm 1 per stage on a Cortex-M, under QEMU with
// -icount shift=0 (one instruction per virtual nanosecond). The SysTick counter runs on
// mps2's 25 MHz reference clock, so one tick is 40 instructions; a calibration loop of a
// known length checks that ratio at start-up. For every scene of the generated set
// (stage_scenes.h: random hands and the extremes) it times, in the core's scalar
// (graspguide::Real: float, or double where the env sets GRASPGUIDE_USE_DOUBLE=1, as
// m7_stages_double does for the M7's double FPU), the stages of the structured route:
//   contact frames | grasp structure (whitened G, rank) | minimum-norm forces, relevance
//   and the unconstrained optimum | QP | motor mapping
// then whole frames through Guidance<T>: cold (fresh solver; a float solve that cannot
// vouch for its answer retries the posture in double there), the SVD reference route, a
// fixed-posture frame, and cold with the retry switched off (full_float). One line per scene goes
// out through semihosting; `graspguide bench --target m4f` (tools/graspguide/bench/targets.py)
// reads them.
#include <cstdint>

#include "graspguide.h"
#include "line_buffer.h"
#include "qemu_halt.h"
#include "semihosting.h"
#include "stage_scenes.h"
#include "systick_counter.h"

namespace {

namespace gg = graspguide;
using stages::elapsed;
using stages::known_loop;
using stages::start_counter;
using stages::ticks;
// The scene set is stored in float (stage_scenes.h), so a double image solves the
// float-rounded inputs: a relative change of about 1e-7 for a hand near the origin, but
// the 1e6 m offsets lose their geometry (targets.py leaves those out of the PWM check).
using T = gg::Real;
constexpr const char* kScalarName = sizeof(T) == sizeof(double) ? "double" : "float";

// Results go through here so the compiler cannot drop the work being timed.
volatile uint32_t g_sink;

template <int K>
void one_scene(const stages::StageScene& c, stages::LineBuffer& line) {
  gg::Contacts<T, K> contacts;
  for (int i = 0; i < K; ++i)
    for (int j = 0; j < 3; ++j) contacts(j, i) = c.contacts[i][j];
  const gg::Vec3<T> y_axis(c.y_axis[0], c.y_axis[1], c.y_axis[2]);
  gg::Vec6<T> wrench;
  for (int j = 0; j < 6; ++j) wrench(j) = c.wrench[j];
  const Eigen::Matrix<T, 4, 1> q(c.orientation[0], c.orientation[1], c.orientation[2],
                                 c.orientation[3]);

  // ---- stages, as solve_grasp and Guidance::update run them; -1 after a failure
  int32_t stage[5] = {-1, -1, -1, -1, -1};
  {
    gg::ContactFrames<T, K> frames;
    gg::GraspStructure<T, K> st;
    gg::ForceSolution<T, K> forces;
    gg::LevelVec<T, K> levels;
    gg::Vec6<T> w, w_hat;
    gg::ForceVec<T, K> lambda0, start;
    uint32_t t0 = ticks();
    gg::Status s = gg::contact_frames<T, K>(contacts, y_axis, frames);
    uint32_t t1 = ticks();
    stage[0] = elapsed(t0, t1);
    if (s == gg::Status::kOk) {
      t0 = ticks();
      s = gg::grasp_structure<T, K>(frames, st);
      t1 = ticks();
      stage[1] = elapsed(t0, t1);
    }
    if (s == gg::Status::kOk) {
      t0 = ticks();
      w = gg::scaled_wrench<T>(wrench, frames.length_scale);
      w_hat = gg::whitened_wrench<T, K>(st, w);
      lambda0 = gg::min_norm_forces<T, K>(st, w_hat);
      const uint8_t relevant = gg::relevance<T, K>(frames, wrench.template head<3>());
      start = gg::project_onto_equilibrium<T, K>(st, w_hat,
                                                 gg::desired_forces<T, K>(lambda0, relevant));
      t1 = ticks();
      stage[2] = elapsed(t0, t1);
      t0 = ticks();
      s = gg::solve_forces<T, K>(frames, st, w, lambda0, start, c.constraints,
                                 gg::kDefaultMaxIterations, forces);
      t1 = ticks();
      stage[3] = elapsed(t0, t1);
    }
    if (s == gg::Status::kOk) {
      t0 = ticks();
      s = gg::motor_levels<T, K>(forces.lambda, c.policy, levels);
      gg::Quat<T> hand;
      if (s == gg::Status::kOk) s = gg::unit_quaternion<T>(q, hand);
      if (s == gg::Status::kOk) {
        const gg::Vec3<T> f_unit = wrench.template head<3>().normalized();
        const gg::Alignment<T> a = gg::alignment<T>(hand, f_unit);
        const T gain = c.mode == gg::Mode::kC ? T(gg::kPwmSpan) : a.alpha;
        g_sink = gg::pwm_from_levels<T, K>(levels, gain).duty[0];
      }
      t1 = ticks();
      stage[4] = elapsed(t0, t1);
    }
  }

  // ---- whole frames
  gg::Scene<T> scene;
  scene.k = K;
  scene.contacts.template leftCols<K>() = contacts;
  scene.y_axis = y_axis;
  scene.constraints = c.constraints;
  scene.policy = c.policy;
  scene.mode = c.mode;
  gg::FrameResult<T> cold, fixed, svd, own;
  int32_t t_fixed = -1;
  // One cold frame of `scene` through a fresh Guidance, in ticks; -1 when the solver
  // refuses the scene or wrench, which is then that frame's status (motors off). `then`
  // runs on the same Guidance afterwards.
  const auto cold_frame = [&](const gg::Scene<T>& sc, gg::FrameResult<T>& out, auto then) {
    gg::Guidance<T> guide;
    if ((out.status = guide.set_scene(sc)) != gg::Status::kOk ||
        (out.status = guide.set_wrench(wrench)) != gg::Status::kOk)
      return int32_t(-1);
    const uint32_t t0 = ticks();
    guide.update(q, out);
    const int32_t t = elapsed(t0, ticks());
    then(guide);
    return t;
  };
  const int32_t t_cold = cold_frame(scene, cold, [&](gg::Guidance<T>& guide) {
    // A 0.5 degree turn about x: the hand moved, the posture did not.
    const Eigen::Matrix<T, 4, 1> turned(
        q(0) * T(0.99999048) - q(1) * T(0.00436331), q(0) * T(0.00436331) + q(1) * T(0.99999048),
        q(2) * T(0.99999048) + q(3) * T(0.00436331), q(3) * T(0.99999048) - q(2) * T(0.00436331));
    const uint32_t t0 = ticks();
    guide.update(turned, fixed);
    t_fixed = elapsed(t0, ticks());
  });
  const auto nothing = [](gg::Guidance<T>&) {};
  // The same cold frame with the retry in double switched off: what float alone costs, so
  // that the baseline guards it apart from the retry (full_cold's maximum on a float image
  // is a posture retried in double).
  gg::Scene<T> own_scene = scene;
  own_scene.solver.double_retry = false;
  const int32_t t_own = cold_frame(own_scene, own, nothing);
  gg::Scene<T> svd_scene = scene;
  svd_scene.solver.decomposition = gg::Decomposition::kSVD;
  const int32_t t_svd = cold_frame(svd_scene, svd, nothing);
  line.str("S ").str(c.name).sp().num(K).sp().str(gg::status_name(cold.status)).sp().str(c.status);
  for (int i = 0; i < gg::kMaxContacts; ++i) line.sp().num(cold.pwm.duty[i]);
  for (int i = 0; i < gg::kMaxContacts; ++i) line.sp().num(c.pwm[i]);
  for (int32_t v : stage) line.sp().num(v);
  line.sp().num(t_cold).sp().num(t_svd).sp().num(t_fixed).sp().num(t_own);
  line.sp().str(gg::status_name(svd.status));
  for (int i = 0; i < gg::kMaxContacts; ++i) line.sp().num(svd.pwm.duty[i]);
  stages::write0(line.end());
}

}  // namespace

int main() {
  start_counter();
  stages::LineBuffer line;
  // Calibration: an empty region and two loops of known length.
  uint32_t t0 = ticks();
  const int32_t empty = elapsed(t0, ticks());
  t0 = ticks();
  known_loop(100000);
  const int32_t loop_a = elapsed(t0, ticks());
  t0 = ticks();
  known_loop(300000);
  const int32_t loop_b = elapsed(t0, ticks());
  stages::write0(line.str("CAL ").num(empty).sp().num(loop_a).sp().num(loop_b).end());
  stages::write0(line.str("SCALAR ").str(kScalarName).end());
  stages::write0(
      line.str("COLUMNS name k status ref_status pwm0 pwm1 pwm2 pwm3 ref0 ref1 ref2 "
               "ref3 frames structure forces qp mapping full_cold full_svd fixed full_float "
               "svd_status svd0 svd1 svd2 svd3")
          .end());
  for (int i = 0; i < stages::kStageSceneCount; ++i) {
    const stages::StageScene& c = stages::kStageScenes[i];
    if (c.k == 3)
      one_scene<3>(c, line);
    else
      one_scene<4>(c, line);
  }
  stages::write0(line.str("STACK ").num(m4f_stack_high_water()).end());
  stages::write0(line.str("END ").num(stages::kStageSceneCount).end());
  stages::exit(0);
}
