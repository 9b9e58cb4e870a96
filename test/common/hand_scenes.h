// Seeded hand-like scenes for property tests (the same recipe as
// tools/graspguide/core/scene_generators.py, drawn with the C++ standard generator).
#pragma once

#include <cmath>
#include <random>

#include "graspguide.h"

namespace graspguide_test {

struct RandomScene {
  int k = 3;
  Eigen::Matrix<double, 3, 4> contacts;
  graspguide::Vec6<double> wrench;
  Eigen::Vector4d orientation;  // [w x y z]
};

// Nominal hand frame: x toward the thumb, y wrist -> fingertips, z out of the palm (m).
inline Eigen::Matrix<double, 3, 4> nominal_hand() {
  Eigen::Matrix<double, 3, 4> c;
  c << 0.045, 0.015, -0.010, 0.000, 0.045, 0.095, 0.100, 0.045, 0.035, 0.040, 0.040, 0.000;
  return c;
}

inline Eigen::Vector3d random_unit(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Vector3d v;
  do {
    v << n(rng), n(rng), n(rng);
  } while (v.norm() < 1e-6);
  return v.normalized();
}

inline RandomScene random_scene(std::mt19937_64& rng, int k) {
  std::uniform_real_distribution<double> jitter(-0.015, 0.015), mag(0.5, 5.0), u(0.0, 1.0),
      mom(0.0, 0.1);
  std::normal_distribution<double> n(0.0, 1.0);
  RandomScene s;
  s.k = k;
  s.contacts = nominal_hand();
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) s.contacts(j, i) += jitter(rng);
  if (k == 3) s.contacts.col(3).setZero();
  s.wrench.head<3>() = random_unit(rng) * mag(rng);
  s.wrench.tail<3>().setZero();
  if (u(rng) < 0.3) s.wrench.tail<3>() = random_unit(rng) * mom(rng);
  Eigen::Vector4d q(n(rng), n(rng), n(rng), n(rng));
  s.orientation = q.normalized();
  return s;
}

template <typename T>
graspguide::Scene<T> make_scene(const RandomScene& r, graspguide::ConstraintModel model,
                                graspguide::Policy policy, graspguide::Mode mode) {
  graspguide::Scene<T> s;
  s.k = r.k;
  s.contacts = r.contacts.cast<T>();
  s.constraints = model;
  s.policy = policy;
  s.mode = mode;
  return s;
}

template <typename T>
struct Solved {
  graspguide::Status status;
  graspguide::FrameResult<T> frame;
  graspguide::GraspSolution<T> grasp;
};

// One frame of a fresh Guidance for a scene: the same path the firmware takes.
template <typename T>
Solved<T> solve_once(const graspguide::Scene<T>& scene, const graspguide::Vec6<double>& wrench,
                     const Eigen::Vector4d& orientation) {
  graspguide::Guidance<T> g;
  Solved<T> out;
  out.status = g.solve(scene, wrench.cast<T>(), orientation.cast<T>(), out.frame);
  out.grasp = g.grasp();
  return out;
}

inline int max_pwm_diff(const graspguide::Pwm& a, const graspguide::Pwm& b) {
  int d = 0;
  for (int i = 0; i < graspguide::kMaxContacts; ++i)
    d = std::max(d, std::abs(int(a.duty[i]) - int(b.duty[i])));
  return d;
}

}  // namespace graspguide_test
