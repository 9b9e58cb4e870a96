// Algorithm 1 per tracker frame. The grasp part (steps 1-6) is kept until the contacts,
// the wrench or the scene change; with a fixed posture a frame costs only the
// orientation error, alpha and the PWM mapping.
#pragma once

#include "graspguide/grasp_solution.h"
#include "graspguide/orientation.h"
#include "graspguide_cue/pwm.h"

namespace graspguide {

template <typename T>
struct FrameResult {
  Status status = Status::kOk;
  Pwm pwm;  // all zero unless status is kOk
  T error_deg = T(0);
  T alpha = T(0);
  bool recomputed = false;  // the grasp part ran in this frame
};

// Whether the scene's contacts form a usable grasp (frames and rank), before any wrench is
// known: what a device checks when a scene arrives, so a bad one is refused at once.
template <typename T, int K>
Status geometry_status_k(const Scene<T>& scene) {
  ContactFrames<T, K> frames;
  const Status s =
      contact_frames<T, K>(scene.contacts.template leftCols<K>(), scene.y_axis, frames);
  if (s != Status::kOk) return s;
  GraspStructure<T, K> st;
  return grasp_structure<T, K>(frames, st);
}

template <typename T>
Status geometry_status(const Scene<T>& scene) {
  if (scene.k != 3 && scene.k != 4) return Status::kBadContactCount;
  return scene.k == 3 ? geometry_status_k<T, 3>(scene) : geometry_status_k<T, 4>(scene);
}

template <typename T>
class Guidance {
 public:
  using ContactsMax = Eigen::Matrix<T, 3, kMaxContacts>;
  using QuatVec = Eigen::Matrix<T, 4, 1>;

  // Checks the scene's parameters (not its geometry: that needs a wrench and is reported
  // by update()).
  Status set_scene(const Scene<T>& scene) {
    if (scene.k != 3 && scene.k != 4) return Status::kBadContactCount;
    if (!scene.y_axis.allFinite() || !scene.contacts.leftCols(scene.k).allFinite())
      return Status::kNonFiniteInput;
    if (!(scene.y_axis.norm() > T(0))) return Status::kBadAxis;
    const Status s = validate_trial_config(scene.trial);
    if (s != Status::kOk) return s;
    if (scene.solver.max_iterations < 1) return Status::kBadConfig;
    scene_ = scene;
    dirty_ = true;
    return Status::kOk;
  }

  Status set_wrench(const Vec6<T>& wrench) {
    if (!wrench.allFinite()) return Status::kNonFiniteInput;
    if (wrench != wrench_) dirty_ = true;
    wrench_ = wrench;
    has_wrench_ = true;
    return Status::kOk;
  }

  // New contact positions (first k columns used); exact comparison decides whether the
  // grasp part must run again.
  Status set_contacts(const ContactsMax& contacts) {
    if (!contacts.leftCols(scene_.k).allFinite()) return Status::kNonFiniteInput;
    if (contacts.leftCols(scene_.k) != scene_.contacts.leftCols(scene_.k)) dirty_ = true;
    scene_.contacts = contacts;
    return Status::kOk;
  }

  // Scene, wrench and pose in one call (the CLI's requests), with one order of checks
  // whatever is wrong: non-finite input, contact count, axis, quaternion, then geometry.
  Status solve(const Scene<T>& scene, const Vec6<T>& wrench, const QuatVec& orientation_wxyz,
               FrameResult<T>& out) {
    out = FrameResult<T>{};
    const int shown = scene.k < 0 ? 0 : (scene.k > kMaxContacts ? kMaxContacts : scene.k);
    if (!scene.contacts.leftCols(shown).allFinite() || !scene.y_axis.allFinite() ||
        !wrench.allFinite() || !orientation_wxyz.allFinite())
      out.status = Status::kNonFiniteInput;
    else if ((out.status = set_scene(scene)) == Status::kOk &&
             (out.status = set_wrench(wrench)) == Status::kOk)
      return update(orientation_wxyz, out);
    return out.status;
  }

  Status update(const QuatVec& orientation_wxyz, FrameResult<T>& out) {
    out = FrameResult<T>{};
    T gravity[3];
    out.status = gravity_in_hand<T>(orientation_wxyz.data(), gravity);
    if (out.status == Status::kOk)
      out.status =
          run(out, [&](const T* f_hat) { return alignment_to_gravity<T>(f_hat, gravity); });
    if (out.status != Status::kOk) out.pwm = Pwm{};  // motors off on any error
    return out.status;
  }

  // The same frame from gravity measured in the hand frame (pointing down, any finite
  // non-zero length): a host-less device's IMU estimate instead of a tracker's orientation.
  Status update_gravity(const T gravity_down[3], FrameResult<T>& out) {
    out = FrameResult<T>{};
    Status checked = Status::kOk;
    out.status = run(out, [&](const T* f_hat) {
      Alignment<T> a;
      checked = alignment_from_gravity<T>(gravity_down, f_hat, a);
      return a;
    });
    if (out.status == Status::kOk) out.status = checked;
    if (out.status != Status::kOk) out.pwm = Pwm{};
    return out.status;
  }

  // The participant's per-motor PWM floor and gain, from the next frame on (the device
  // checks it with check_calibration first). Kept across scenes and wrenches.
  void set_calibration(const MotorCalibration& calibration) {
    calibration_ = calibration;
    if (!dirty_) pwm_plan_ = plan_pwm<T>(grasp_.levels.data(), kMaxContacts, calibration_);
  }

  const MotorCalibration& calibration() const { return calibration_; }
  const GraspSolution<T>& grasp() const { return grasp_; }
  const Scene<T>& scene() const { return scene_; }

 private:
  // align(f_hat) -> Alignment: the frame's gravity, from a quaternion or an IMU.
  template <class Align>
  Status run(FrameResult<T>& out, Align&& align) {
    if (!has_wrench_) return Status::kZeroWrench;
    if (dirty_) {
      grasp_status_ = scene_.k == 3 ? solve_k<3>() : solve_k<4>();
      pwm_plan_ = plan_pwm<T>(grasp_.levels.data(), kMaxContacts, calibration_);
      dirty_ = false;
      out.recomputed = true;
    }
    if (grasp_status_ != Status::kOk) return grasp_status_;
    // The rest is the per-frame layer's: what a frame costs while the posture holds.
    const Alignment<T> a = align(grasp_.force_unit.data());
    out.error_deg = a.error_deg;
    out.alpha = a.alpha;
    out.pwm = pwm_from_plan(pwm_plan_, pwm_gain(scene_.mode, a.alpha));
    return Status::kOk;
  }

  template <int K>
  Status solve_k() {
    GraspSolution<T> next;
    const Contacts<T, K> c = scene_.contacts.template leftCols<K>();
    const Status s = solve_grasp<T, K>(c, wrench_, scene_.y_axis, scene_.constraints, scene_.policy,
                                       scene_.solver, next);
    grasp_ = next;
    return s;
  }

  Scene<T> scene_;
  Vec6<T> wrench_ = Vec6<T>::Zero();
  bool has_wrench_ = false;
  bool dirty_ = true;
  Status grasp_status_ = Status::kOk;
  GraspSolution<T> grasp_;
  MotorCalibration calibration_;  // the identity until set
  PwmPlan<T> pwm_plan_;           // the posture's part of the PWM
};

}  // namespace graspguide
