// Steps 1-6 for one posture and wrench: everything that does not depend on the hand's
// orientation, so it can be kept while the posture stays fixed.
#pragma once

#include "graspguide/answer_certificate.h"
#include "graspguide/force_qp.h"
#include "graspguide/motor_levels.h"
#include "graspguide/relevance.h"
#include "graspguide/svd_route.h"

namespace graspguide {

// Sized for the largest scene; a k-contact scene fills the first k (3k) entries.
template <typename T>
struct GraspSolution {
  int k = 0;
  Eigen::Matrix<T, 3 * kMaxContacts, 1> lambda = Eigen::Matrix<T, 3 * kMaxContacts, 1>::Zero();
  Eigen::Matrix<T, kMaxContacts, 1> levels = Eigen::Matrix<T, kMaxContacts, 1>::Zero();
  Vec3<T> force_unit = Vec3<T>::Zero();  // f_hat, hand frame
  ConstraintModel used = ConstraintModel::kNone;
  uint8_t relevant_mask = 0;
  uint8_t fallback_mask = 0;
  uint16_t active = 0;
  int iterations = 0;
  T rank_ratio = T(0);
  bool retried = false;  // a float solve that could not vouch for its answer ran in double
};

// Steps 2-5 for the chosen route: the rank, lambda0 (for the relevance) and the QP optimum.
template <typename T, int K>
Status grasp_forces(const ContactFrames<T, K>& frames, const Vec6<T>& w, const Vec3<T>& force,
                    ConstraintModel model, const SolverSettings& settings, T& rank_ratio,
                    uint8_t& relevant, ForceSolution<T, K>& forces) {
  if (settings.decomposition == Decomposition::kSVD) {
#if GRASPGUIDE_WITH_SVD_ROUTE
    GraspMat<T, K> g;
    grasp_matrix<T, K>(frames, g);
    Equilibrium<T, K> eq;
    const Status s = equilibrium_svd<T, K>(g, w, eq);
    rank_ratio = eq.rank_ratio;
    if (s != Status::kOk) return s;
    relevant = relevance<T, K>(frames, force);
    forces.active = 0;
    return solve_forces_svd<T, K>(eq, desired_forces<T, K>(eq.lambda0, relevant), model,
                                  settings.max_iterations, forces.lambda, forces.used,
                                  forces.iterations);
#else
    return Status::kBadConfig;
#endif
  }
  GraspStructure<T, K> st;
  const Status s = grasp_structure<T, K>(frames, st);
  rank_ratio = st.rank_ratio;
  if (s != Status::kOk) return s;
  const Vec6<T> w_hat = whitened_wrench<T, K>(st, w);
  const ForceVec<T, K> lambda0 = min_norm_forces<T, K>(st, w_hat);
  relevant = relevance<T, K>(frames, force);
  const ForceVec<T, K> start =
      project_onto_equilibrium<T, K>(st, w_hat, desired_forces<T, K>(lambda0, relevant));
  const Status qp =
      solve_forces<T, K>(frames, st, w, lambda0, start, model, settings.max_iterations, forces);
  // Double answers for itself: the certificate is float's, and the retry's.
  if (qp == Status::kOk && sizeof(T) < sizeof(double))
    forces.certain = answer_certain<T, K>(st, w_hat, lambda0, forces);
  return qp;
}

// Steps 1-6 once, in T. `certain` is false when a float solve cannot vouch for its
// answer (answer_certificate.h) or hit the iteration cap; out then holds float's answer,
// if any. Never inlined, so that its frame is gone before a retry pushes the double one:
// the M4F firmware's stack peak is the larger of the two, not their sum.
template <typename T, int K>
__attribute__((noinline)) Status solve_grasp_once(const Contacts<T, K>& contacts,
                                                  const Vec6<T>& wrench, const Vec3<T>& y_axis,
                                                  ConstraintModel model, Policy policy,
                                                  const SolverSettings& settings,
                                                  GraspSolution<T>& out, bool& certain) {
  certain = true;
  if (!wrench.allFinite()) return Status::kNonFiniteInput;
  ContactFrames<T, K> frames;
  Status s = contact_frames<T, K>(contacts, y_axis, frames);
  if (s != Status::kOk) return s;
  const Vec6<T> w = scaled_wrench<T>(wrench, frames.length_scale);
  const T w_norm = w.stableNorm();
  if (!(w_norm > T(0))) return Status::kZeroWrench;
  const Vec3<T> force = wrench.template head<3>();
  const T f_norm = force.stableNorm();
  if (!(f_norm > T(kZeroForceRelTol) * w_norm)) return Status::kZeroForce;

  uint8_t relevant = 0;
  ForceSolution<T, K> forces;
  s = grasp_forces<T, K>(frames, w, force, model, settings, out.rank_ratio, relevant, forces);
  out.iterations = forces.iterations;
  certain = s == Status::kOk ? forces.certain : s != Status::kQpIterationLimit;
  if (s != Status::kOk) return s;

  LevelVec<T, K> levels;
  s = motor_levels<T, K>(forces.lambda, policy, levels);
  if (s != Status::kOk) return s;

  out.k = K;
  out.lambda.setZero();
  out.lambda.template head<3 * K>() = forces.lambda;
  out.levels.setZero();
  out.levels.template head<K>() = levels;
  out.force_unit = force / f_norm;
  out.used = forces.used;
  out.relevant_mask = relevant;
  out.fallback_mask = frames.fallback_mask;
  out.active = forces.active;
  return Status::kOk;
}

// The whole solve again in double from the same (float) inputs, its answer rounded back.
template <typename T, int K>
__attribute__((noinline)) Status retried_in_double(const Contacts<T, K>& contacts,
                                                   const Vec6<T>& wrench, const Vec3<T>& y_axis,
                                                   ConstraintModel model, Policy policy,
                                                   const SolverSettings& settings,
                                                   GraspSolution<T>& out) {
  GraspSolution<double> d;
  bool certain = true;  // double vouches for itself
  const Status s = solve_grasp_once<double, K>(
      contacts.template cast<double>(), wrench.template cast<double>(),
      y_axis.template cast<double>(), model, policy, settings, d, certain);
  const int float_iterations = out.iterations;
  out = GraspSolution<T>{};
  out.k = d.k;
  out.lambda = d.lambda.template cast<T>();
  out.levels = d.levels.template cast<T>();
  out.force_unit = d.force_unit.template cast<T>();
  out.used = d.used;
  out.relevant_mask = d.relevant_mask;
  out.fallback_mask = d.fallback_mask;
  out.active = d.active;
  out.iterations = float_iterations + d.iterations;
  out.rank_ratio = T(d.rank_ratio);
  out.retried = true;
  return s;
}

// Steps 1-6, and in a float build the retry in double of an answer float cannot vouch for.
template <typename T, int K>
Status solve_grasp(const Contacts<T, K>& contacts, const Vec6<T>& wrench, const Vec3<T>& y_axis,
                   ConstraintModel model, Policy policy, const SolverSettings& settings,
                   GraspSolution<T>& out) {
  bool certain = true;
  const Status s =
      solve_grasp_once<T, K>(contacts, wrench, y_axis, model, policy, settings, out, certain);
  if (certain || !settings.double_retry || sizeof(T) >= sizeof(double)) return s;
  return retried_in_double<T, K>(contacts, wrench, y_axis, model, policy, settings, out);
}

// Declared here with EXTERN = extern, defined once in grasp_solution.cpp with EXTERN empty.
#define GRASPGUIDE_GRASP_SOLUTION(EXTERN, T, K)                                                   \
  EXTERN template Status solve_grasp<T, K>(const Contacts<T, K>&, const Vec6<T>&, const Vec3<T>&, \
                                           ConstraintModel, Policy, const SolverSettings&,        \
                                           GraspSolution<T>&);                                    \
  EXTERN template Status solve_forces<T, K>(const ContactFrames<T, K>&,                           \
                                            const GraspStructure<T, K>&, const Vec6<T>&,          \
                                            const ForceVec<T, K>&, const ForceVec<T, K>&,         \
                                            ConstraintModel, int, ForceSolution<T, K>&, T);
#define GRASPGUIDE_GRASP_SOLUTIONS(EXTERN)    \
  GRASPGUIDE_GRASP_SOLUTION(EXTERN, float, 3) \
  GRASPGUIDE_GRASP_SOLUTION(EXTERN, float, 4) \
  GRASPGUIDE_GRASP_SOLUTION(EXTERN, double, 3) GRASPGUIDE_GRASP_SOLUTION(EXTERN, double, 4)
#ifndef GRASPGUIDE_INSTANTIATING_GRASP_SOLUTION
GRASPGUIDE_GRASP_SOLUTIONS(extern)
#endif

}  // namespace graspguide
