// The whole pipeline against the independent float64 reference
// (tools/graspguide/core/reference.py -> test/data/known_answers.h): random hand-like scenes
// for every policy, mode and constraint model, and the extreme cases.
#include <gtest/gtest.h>

#include <cstring>

#include "common/hand_scenes.h"
#include "data/known_answers.h"
#include "graspguide.h"

namespace gg = graspguide;
using graspguide_test::kKnownAnswers;
using graspguide_test::KnownAnswer;

template <typename T>
graspguide_test::Solved<T> run_case(const KnownAnswer& ka) {
  gg::Scene<T> scene;
  scene.k = ka.k;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) scene.contacts(j, i) = T(ka.contacts[i][j]);
  scene.y_axis = gg::Vec3<T>(T(ka.y_axis[0]), T(ka.y_axis[1]), T(ka.y_axis[2]));
  EXPECT_TRUE(gg::parse_constraint_model(ka.constraints, &scene.constraints)) << ka.name;
  EXPECT_TRUE(gg::parse_policy(ka.policy, &scene.policy)) << ka.name;
  EXPECT_TRUE(gg::parse_mode(ka.mode, &scene.mode)) << ka.name;
  gg::Vec6<double> w;
  for (int j = 0; j < 6; ++j) w(j) = ka.wrench[j];
  const Eigen::Vector4d q(ka.orientation[0], ka.orientation[1], ka.orientation[2],
                          ka.orientation[3]);
  return graspguide_test::solve_once<T>(scene, w, q);
}

TEST(KnownAnswers, TheDataSetCoversEveryCombination) {
  int k3 = 0, k4 = 0, extremes = 0, fell_back = 0;
  for (const auto& ka : kKnownAnswers) {
    (ka.k == 3 ? k3 : k4)++;
    if (std::strncmp(ka.name, "random", 6) != 0) ++extremes;
    if (std::strcmp(ka.status, "ok") == 0 && std::strcmp(ka.constraints, ka.constraints_used) != 0)
      ++fell_back;
  }
  EXPECT_GE(k3, 100);
  EXPECT_GE(k4, 100);
  EXPECT_GE(extremes, 15);
  EXPECT_GE(fell_back, 10);  // infeasible paper scenes are in the set
}

TEST(KnownAnswers, DoubleMatchesTheReference) {
  int compared = 0;
  for (const auto& ka : kKnownAnswers) {
    SCOPED_TRACE(ka.name);
    const auto r = run_case<double>(ka);
    ASSERT_STREQ(gg::status_name(r.status), ka.status);
    if (r.status != gg::Status::kOk) {
      for (int i = 0; i < 4; ++i) EXPECT_EQ(r.frame.pwm.duty[i], 0);  // motors off
      continue;
    }
    ++compared;
    EXPECT_STREQ(gg::constraint_model_name(r.grasp.used), ka.constraints_used);
    double diff = 0, ref = 0;
    for (int j = 0; j < 3 * ka.k; ++j) {
      diff += std::pow(r.grasp.lambda(j) - ka.lambda[j], 2);
      ref += ka.lambda[j] * ka.lambda[j];
    }
    EXPECT_LE(std::sqrt(diff), 1e-6 * std::sqrt(ref));
    for (int i = 0; i < ka.k; ++i) {
      EXPECT_LE(std::abs(int(r.frame.pwm.duty[i]) - ka.pwm[i]), 1) << "motor " << i;
      EXPECT_NEAR(r.grasp.levels(i), ka.levels[i], 1e-6) << "motor " << i;
      EXPECT_EQ(bool(r.grasp.relevant_mask & (1u << i)), bool(ka.relevant[i])) << "contact " << i;
    }
    EXPECT_EQ(r.grasp.fallback_mask, ka.fallback_mask);
    EXPECT_NEAR(r.frame.error_deg, ka.error_deg, 1e-6);
  }
  EXPECT_GT(compared, 200);
}

TEST(KnownAnswers, FloatMatchesTheReferenceWithinOnePwmCount) {
  int compared = 0, exact = 0, refused = 0;
  for (const auto& ka : kKnownAnswers) {
    SCOPED_TRACE(ka.name);
    const auto r = run_case<float>(ka);
    // Float may refuse a hand its rounding cannot resolve, never render it distorted.
    if (r.status == gg::Status::kImpreciseContacts && std::strcmp(ka.status, "ok") == 0) {
      EXPECT_NE(std::strstr(ka.name, "offset_1e6"), nullptr);
      ++refused;
      continue;
    }
    ASSERT_STREQ(gg::status_name(r.status), ka.status);
    if (r.status != gg::Status::kOk) continue;
    ++compared;
    EXPECT_STREQ(gg::constraint_model_name(r.grasp.used), ka.constraints_used);
    int worst = 0;
    for (int i = 0; i < ka.k; ++i)
      worst = std::max(worst, std::abs(int(r.frame.pwm.duty[i]) - ka.pwm[i]));
    EXPECT_LE(worst, 1);
    exact += worst == 0;
  }
  EXPECT_GT(compared, 200);
  std::printf(
      "float vs float64 reference: %d/%d scenes with identical PWM, %d refused as "
      "imprecise_contacts\n",
      exact, compared, refused);
}
