// Per-motor calibration (motor_calibration.h, pwm.h): the identity is the paper's mapping
// bit for bit, a calibrated plan gives the formula's numbers, bad values are refused by
// name, and the full-solve device renders TELEMETRY with it.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <vector>

#include "common/hand_scenes.h"
#include "graspguide_device/link_device.h"
#include "graspguide_hal/fake_hal.h"

namespace gg = graspguide;
namespace gd = graspguide::device;
namespace gl = graspguide::link;
namespace gh = graspguide::hal;

namespace {

// docs/calibration.md's formula written out independently of pwm.h, in T.
template <typename T>
int formula(T level, T g, int floor_i, float gain_i) {
  const T a = std::fabs(level);
  if (!(a > T(gg::kMotorOffLevel))) return 0;
  const T duty = std::floor((T(floor_i) + g * (T(gain_i) * a)) + T(0.5));
  return duty < T(0) ? 0 : (duty > T(255) ? 255 : int(duty));
}

template <typename T>
class CalibrationTest : public ::testing::Test {};
using Scalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(CalibrationTest, Scalars);

TYPED_TEST(CalibrationTest, TheIdentityIsTheUncalibratedMappingBitForBit) {
  using T = TypeParam;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> level(-1.2, 1.2), gain(-50, 600);
  const gg::MotorCalibration identity;
  int on = 0;
  for (int i = 0; i < 100000; ++i) {
    const T l[4] = {T(level(rng)), T(level(rng)), T(level(rng)), T(level(rng))};
    const gg::PwmPlan<T> a = gg::plan_pwm(l, 4), b = gg::plan_pwm(l, 4, identity);
    ASSERT_EQ(a.gain_limit, b.gain_limit);
    const T g = T(gain(rng));
    const gg::Pwm pa = gg::pwm_from_plan(a, g), pb = gg::pwm_from_plan(b, g);
    for (int m = 0; m < 4; ++m) {
      ASSERT_EQ(pa.duty[m], pb.duty[m]);
      ASSERT_EQ(pb.duty[m], formula(l[m], g, gg::kPwmMin, 1.0f));
      on += pb.duty[m] > 0;
    }
  }
  EXPECT_GT(on, 100000);
}

TYPED_TEST(CalibrationTest, ACalibratedPlanGivesTheFormulasNumbers) {
  using T = TypeParam;
  std::mt19937 rng(12);
  std::uniform_real_distribution<double> level(-1.2, 1.2), gain(-50, 600), cal_gain(0.25, 4.0);
  std::uniform_int_distribution<int> floor(0, gg::kCalibrationFloorMax);
  int checked = 0, clamped = 0;
  for (int i = 0; i < 20000; ++i) {
    gg::MotorCalibration c;
    for (int m = 0; m < 4; ++m) {
      c.pwm_floor[m] = uint8_t(floor(rng));
      c.gain[m] = float(cal_gain(rng));
    }
    if (i % 7 == 0) c.gain[i % 4] = gg::kCalibrationGainMax;
    ASSERT_EQ(gg::check_calibration(c), gg::CalibrationCheck::kOk);
    const T l[4] = {T(level(rng)), T(level(rng)), T(level(rng)), T(level(rng))};
    const gg::PwmPlan<T> plan = gg::plan_pwm(l, 4, c);
    // Gains around the plan's limit too, where the per-motor clamp starts to matter.
    for (const T g : {T(gain(rng)), plan.gain_limit, plan.gain_limit * T(1.001), T(gg::kPwmSpan)}) {
      const gg::Pwm p = gg::pwm_from_plan(plan, g);
      for (int m = 0; m < 4; ++m, ++checked) {
        ASSERT_EQ(p.duty[m], formula(l[m], g, c.pwm_floor[m], c.gain[m]))
            << "level " << l[m] << " G " << g << " floor " << int(c.pwm_floor[m]) << " gain "
            << c.gain[m];
        clamped += p.duty[m] == 255;
      }
    }
  }
  EXPECT_GT(checked, 0);
  EXPECT_GT(clamped, 0);
}

TEST(Calibration, EachBadValueIsRefusedByName) {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  struct Bad {
    int motor;
    int floor;
    float gain;
    gg::CalibrationCheck check;
    gg::CalibrationField field;
  };
  const Bad cases[] = {
      {0, 255, 1.0f, gg::CalibrationCheck::kPwmFloorTooHigh, gg::CalibrationField::kPwmFloor},
      {3, 70, nan, gg::CalibrationCheck::kGainNotFinite, gg::CalibrationField::kGain},
      {1, 70, inf, gg::CalibrationCheck::kGainNotFinite, gg::CalibrationField::kGain},
      {2, 70, 0.2499f, gg::CalibrationCheck::kGainOutOfRange, gg::CalibrationField::kGain},
      {2, 70, 4.001f, gg::CalibrationCheck::kGainOutOfRange, gg::CalibrationField::kGain},
      {0, 70, -1.0f, gg::CalibrationCheck::kGainOutOfRange, gg::CalibrationField::kGain},
  };
  for (const Bad& b : cases) {
    gg::MotorCalibration c;
    c.pwm_floor[b.motor] = uint8_t(b.floor);
    c.gain[b.motor] = b.gain;
    uint8_t motor = 99;
    EXPECT_EQ(gg::check_calibration(c, &motor), b.check) << b.floor << " " << b.gain;
    EXPECT_EQ(motor, b.motor);
    EXPECT_EQ(gg::calibration_field(b.check), b.field);
  }
  gg::MotorCalibration edges;
  edges.pwm_floor[0] = 0;
  edges.pwm_floor[1] = gg::kCalibrationFloorMax;
  edges.gain[2] = gg::kCalibrationGainMin;
  edges.gain[3] = gg::kCalibrationGainMax;
  EXPECT_EQ(gg::check_calibration(edges), gg::CalibrationCheck::kOk);
  EXPECT_TRUE(gg::is_identity(gg::MotorCalibration{}));
  EXPECT_FALSE(gg::is_identity(edges));
}

// ---- the full-solve device
struct Rig {
  gh::FakeClock clock;
  gh::RecordingMotors motors;
  gd::Application app{motors, clock};
  gh::MemoryStream stream;
  gd::DeviceInfo info;
  std::unique_ptr<gd::LinkDevice> device;
  gl::FrameParser parser{gl::Accept::kDeviceToHost};
  gl::SequenceCounter seq;

  Rig() { device = std::make_unique<gd::LinkDevice>(stream, app, info); }

  template <class Reply, class Msg>
  Reply ask(const Msg& m) {
    uint8_t out[gl::kMaxWireFrameSize];
    size_t n = 0;
    EXPECT_EQ(gl::write_frame(m, seq.next(), out, sizeof out, &n), gl::LinkStatus::kOk);
    stream.host_send(out, n);
    device->poll();
    uint8_t buf[1024];
    const size_t got = stream.host_receive(buf, sizeof buf);
    Reply r;
    int frames = 0;
    for (size_t i = 0; i < got; ++i) {
      if (parser.push(buf[i]) != gl::ParseEvent::kFrame) continue;
      ++frames;
      const auto& f = parser.frame();
      EXPECT_EQ(f.header.msg_id, uint8_t(Reply::kId)) << gl::message_name(f.header.msg_id);
      if (f.header.msg_id == uint8_t(Reply::kId)) {
        EXPECT_EQ(gl::unpack(f.payload, f.payload_size, &r), gl::LinkStatus::kOk);
      }
    }
    EXPECT_EQ(frames, 1);
    return r;
  }
};

gl::SetScene scene_msg(gl::Mode mode) {
  gl::SetScene m;
  m.k = 4;
  m.mode = mode;
  const auto c = graspguide_test::nominal_hand();
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) m.contacts[i][j] = float(c(j, i));
  return m;
}

gl::StartTrial trial_msg() {
  gl::StartTrial m;
  m.trial_id = 3;
  const float w[6] = {0.4f, -1.0f, 0.3f, 0, 0, 0};
  std::copy(w, w + 6, m.wrench);
  return m;
}

gl::SetCalibration calibration_msg() {
  gl::SetCalibration m;
  const uint8_t floors[4] = {55, 90, 0, 140};
  const float gains[4] = {1.5f, 0.25f, 4.0f, 0.8f};
  std::copy(floors, floors + 4, m.pwm_floor);
  std::copy(gains, gains + 4, m.gain);
  return m;
}

TEST(CalibrationDevice, TelemetryIsRenderedWithTheCalibration) {
  for (const gl::Mode mode : {gl::Mode::kC, gl::Mode::kV}) {
    Rig r;
    const gl::SetCalibration cal = calibration_msg();
    r.ask<gl::Ack>(cal);
    r.ask<gl::Ack>(scene_msg(mode));
    r.ask<gl::Ack>(trial_msg());
    // The reference: the core's levels and alpha for the same pose, mapped by the formula.
    gg::Scene<gg::Real> scene;
    scene.k = 4;
    scene.mode = static_cast<gg::Mode>(mode);
    scene.contacts = graspguide_test::nominal_hand().cast<gg::Real>();
    gg::Vec6<double> w;
    w << 0.4, -1.0, 0.3, 0, 0, 0;
    std::mt19937_64 rng(21);
    int driven = 0;
    for (int n = 0; n < 30; ++n) {
      const auto rs = graspguide_test::random_scene(rng, 4);
      gl::Pose p;
      p.host_time_us = uint32_t(n * 4000);
      for (int j = 0; j < 4; ++j) p.quat_wxyz[j] = float(rs.orientation(j));
      const auto t = r.ask<gl::Telemetry>(p);
      ASSERT_EQ(t.solver_status, gl::ErrorCode::kOk);
      const auto ref = graspguide_test::solve_once<gg::Real>(scene, w, rs.orientation);
      const gg::Real g = gg::pwm_gain(scene.mode, ref.frame.alpha);
      for (int i = 0; i < 4; ++i) {
        const int expect = formula<gg::Real>(ref.grasp.levels(i), g, cal.pwm_floor[i], cal.gain[i]);
        EXPECT_EQ(t.pwm[i], expect) << n << " motor " << i;
        EXPECT_EQ(r.motors.last().duty[i], expect);
        driven += expect > 0 && expect != gg::kPwmMin;
      }
    }
    EXPECT_GT(driven, 0);
  }
}

TEST(CalibrationDevice, RefusalsNameTheFieldAndKeepThePreviousCalibration) {
  Rig r;
  gl::SetCalibration floor = calibration_msg();
  floor.pwm_floor[2] = 255;
  auto e = r.ask<gl::Error>(floor);
  EXPECT_EQ(e.code, gl::ErrorCode::kBadConfig);
  EXPECT_EQ(e.detail, 0);  // pwm_floor
  for (const float bad : {std::numeric_limits<float>::quiet_NaN(), 0.1f, 5.0f,
                          std::numeric_limits<float>::infinity()}) {
    gl::SetCalibration gain = calibration_msg();
    gain.gain[1] = bad;
    e = r.ask<gl::Error>(gain);
    EXPECT_EQ(e.code, gl::ErrorCode::kBadConfig);
    EXPECT_EQ(e.detail, 1);  // gain
  }
  EXPECT_TRUE(gg::is_identity(r.app.calibration()));
  r.ask<gl::Ack>(scene_msg(gl::Mode::kC));
  r.ask<gl::Ack>(trial_msg());
  e = r.ask<gl::Error>(calibration_msg());
  EXPECT_EQ(e.code, gl::ErrorCode::kNotAllowedInState);
  EXPECT_EQ(e.detail, uint8_t(gl::DeviceState::kTrialRunning));
  EXPECT_TRUE(gg::is_identity(r.app.calibration()));
  r.ask<gl::Ack>(gl::Stop{});
  r.ask<gl::Ack>(calibration_msg());
  EXPECT_EQ(r.app.calibration().pwm_floor[0], calibration_msg().pwm_floor[0]);
  // SET_MOTORS stays raw: calibration measures with it.
  gl::SetMotors raw;
  raw.pwm[0] = 33;
  r.ask<gl::Ack>(raw);
  EXPECT_EQ(r.motors.last().duty[0], 33);
}

}  // namespace
