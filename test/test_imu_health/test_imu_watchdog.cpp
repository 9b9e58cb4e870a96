// The IMU health rule (graspguide_cue/imu_watchdog.h): stale, stuck and out-of-range IMUs,
// recovery, fault counts, the wrap of the microsecond clock, and that a fault turns the
// motors off.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <string>

#include "graspguide_cue/imu_watchdog.h"
#include "graspguide_hal/fake_hal.h"

namespace gg = graspguide;
namespace gh = graspguide::hal;

namespace {

constexpr uint32_t kPeriodUs = 10000;  // 100 Hz, the rate the defaults are argued for
constexpr double kGravityMps2 = 9.80665;
constexpr double kPi = 3.14159265358979323846;
// An LSM6DSOX set to +-8 g and +-2000 dps, as src/boards/arduino sets it.
constexpr double kAccelFullScaleMps2 = 8 * kGravityMps2;
constexpr double kGyroFullScaleRadps = 2000 * kPi / 180;

template <typename T>
gg::ImuWatchdogConfig<T> lsm_config() {
  gg::ImuWatchdogConfig<T> c;
  c.accel_full_scale_mps2 = T(kAccelFullScaleMps2);
  c.gyro_full_scale_radps = T(kGyroFullScaleRadps);
  return c;
}

// A live part at rest: gravity on z plus a different small wobble on every channel, so no
// two consecutive readings are equal (as a sensor's noise makes them).
template <typename T>
struct LiveStream {
  uint32_t n = 0;
  void next(T (&a)[3], T (&g)[3]) {
    ++n;
    for (int i = 0; i < 3; ++i) {
      a[i] = T(0.01 * ((n * (i + 3)) % 7));
      g[i] = T(0.001 * ((n * (i + 2)) % 5 + 1) * (n % 2 ? 1 : -1));
    }
    a[2] += T(kGravityMps2);
  }
};

template <typename T>
class ImuWatchdogTest : public ::testing::Test {
 protected:
  // Feeds `count` live samples one period apart, polling before each; returns the last status.
  gg::Status feed_live(gg::ImuWatchdog<T>& w, uint32_t& t_us, int count) {
    gg::Status s = w.status();
    for (int i = 0; i < count; ++i) {
      t_us += kPeriodUs;
      EXPECT_EQ(w.poll(t_us), w.status());
      T a[3], g[3];
      live_.next(a, g);
      s = w.on_sample(a, g, t_us);
    }
    return s;
  }
  LiveStream<T> live_;
};

using Scalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(ImuWatchdogTest, Scalars);

TYPED_TEST(ImuWatchdogTest, EveryBadSettingIsRefusedAndItsWatchdogNeverAllowsTheMotors) {
  using T = TypeParam;
  ASSERT_EQ(gg::validate_imu_watchdog_config(lsm_config<T>()), gg::Status::kOk);
  const T inf = std::numeric_limits<T>::infinity();
  const T nan = std::numeric_limits<T>::quiet_NaN();
  gg::ImuWatchdogConfig<T> bad[11];
  for (auto& c : bad) c = lsm_config<T>();
  bad[0].stale_ms = 0;
  bad[1].stale_ms = gg::kImuMaxStaleMs + 1;
  bad[2].stuck_samples = 1;
  bad[3].recovery_samples = 0;
  bad[4].accel_full_scale_mps2 = T(0);
  bad[5].accel_full_scale_mps2 = -T(1);
  bad[6].accel_full_scale_mps2 = inf;
  bad[7].gyro_full_scale_radps = nan;
  bad[8].gyro_full_scale_radps = T(0);
  bad[9].gyro_full_scale_radps = inf;
  bad[10] = gg::ImuWatchdogConfig<T>{};  // the board never said its ranges
  for (const auto& c : bad) {
    EXPECT_EQ(gg::validate_imu_watchdog_config(c), gg::Status::kBadImuConfig);
    gg::ImuWatchdog<T> w(c, 0);
    uint32_t t = 0;
    EXPECT_EQ(this->feed_live(w, t, 3 * c.recovery_samples + 3), gg::Status::kBadImuConfig);
    EXPECT_FALSE(w.motors_allowed());
    EXPECT_EQ(w.samples(), 0u);
  }
}

TYPED_TEST(ImuWatchdogTest, MotorsWaitForRecoverySamplesAfterStart) {
  using T = TypeParam;
  const auto c = lsm_config<T>();
  uint32_t t = 12345;
  gg::ImuWatchdog<T> w(c, t);
  EXPECT_EQ(w.status(), gg::Status::kImuStale);
  EXPECT_FALSE(w.motors_allowed());
  EXPECT_EQ(this->feed_live(w, t, c.recovery_samples - 1), gg::Status::kImuStale);
  EXPECT_FALSE(w.motors_allowed());
  EXPECT_EQ(this->feed_live(w, t, 1), gg::Status::kOk);
  EXPECT_TRUE(w.motors_allowed());
  EXPECT_EQ(w.faults().stale, 0u);  // waiting for the first samples is not a fault
  EXPECT_EQ(w.samples(), uint32_t(c.recovery_samples));
}

TYPED_TEST(ImuWatchdogTest, NoSampleForTheStaleTimeIsAFaultCountedOnceUntilSamplesResume) {
  using T = TypeParam;
  const auto c = lsm_config<T>();
  uint32_t t = 0;
  gg::ImuWatchdog<T> w(c, t);
  ASSERT_EQ(this->feed_live(w, t, c.recovery_samples), gg::Status::kOk);
  const uint32_t last = t;
  const uint32_t stale_us = c.stale_ms * 1000u;
  EXPECT_EQ(w.poll(last + stale_us - 1), gg::Status::kOk);
  EXPECT_EQ(w.poll(last + stale_us), gg::Status::kImuStale);
  EXPECT_FALSE(w.motors_allowed());
  EXPECT_EQ(w.poll(last + 10 * stale_us), gg::Status::kImuStale);
  EXPECT_EQ(w.faults().stale, 1u);
  // Samples again: the fault ends only after recovery_samples good ones.
  t = last + 10 * stale_us;
  EXPECT_EQ(this->feed_live(w, t, c.recovery_samples - 1), gg::Status::kImuStale);
  EXPECT_EQ(this->feed_live(w, t, 1), gg::Status::kOk);
  EXPECT_EQ(w.faults().stale, 1u);
  EXPECT_EQ(w.faults().stuck + w.faults().out_of_range, 0u);
}

TYPED_TEST(ImuWatchdogTest, StaleTimeIsMeasuredAcrossTheWrapOfTheMicrosecondClock) {
  using T = TypeParam;
  const auto c = lsm_config<T>();
  const uint32_t stale_us = c.stale_ms * 1000u;
  uint32_t t = 0xFFFFFFFFu - uint32_t(c.recovery_samples) * kPeriodUs - 1000u;
  gg::ImuWatchdog<T> w(c, t);
  ASSERT_EQ(this->feed_live(w, t, c.recovery_samples), gg::Status::kOk);
  const uint32_t last = t;  // 1 ms before the wrap
  ASSERT_GT(last, 0xFFFFFFFFu - stale_us);
  EXPECT_EQ(w.poll(last + stale_us - 1), gg::Status::kOk);  // past the wrap, not yet stale
  EXPECT_LT(last + stale_us - 1, last);
  EXPECT_EQ(w.poll(last + stale_us), gg::Status::kImuStale);
  // Samples across the wrap keep it healthy.
  gg::ImuWatchdog<T> v(c, 0xFFFFFFFFu - 5 * kPeriodUs);
  uint32_t u = 0xFFFFFFFFu - 5 * kPeriodUs;
  EXPECT_EQ(this->feed_live(v, u, 3 * c.recovery_samples), gg::Status::kOk);
  EXPECT_LT(u, 0xFFFFFFFFu - 5 * kPeriodUs);  // the stream did wrap
}

TYPED_TEST(ImuWatchdogTest, ASampleReadAfterThePollsNowIsNotOld) {
  using T = TypeParam;
  const auto c = lsm_config<T>();
  uint32_t t = 0;
  gg::ImuWatchdog<T> w(c, t);
  ASSERT_EQ(this->feed_live(w, t, c.recovery_samples), gg::Status::kOk);
  // The loop took "now" just before reading the sample: now - sample time is -1 us, which an
  // unsigned difference would read as 71 minutes.
  EXPECT_EQ(w.poll(t - 1), gg::Status::kOk);
  EXPECT_EQ(w.faults().stale, 0u);
}

TYPED_TEST(ImuWatchdogTest, AStaleFaultLastsUntilASampleHoweverLongThePollsGoOn) {
  using T = TypeParam;
  const auto c = lsm_config<T>();
  uint32_t t = 0;
  gg::ImuWatchdog<T> w(c, t);
  ASSERT_EQ(this->feed_live(w, t, c.recovery_samples), gg::Status::kOk);
  // Poll every 10 s for 3 hours: past 2^31 us the signed difference turns negative.
  uint32_t now = t;
  for (int i = 0; i < 3 * 360; ++i) {
    now += 10000000u;
    EXPECT_EQ(w.poll(now), gg::Status::kImuStale);
  }
  EXPECT_EQ(w.faults().stale, 1u);
}

TYPED_TEST(ImuWatchdogTest, TheSameReadingStuckSamplesTimesInARowIsAFault) {
  using T = TypeParam;
  const auto c = lsm_config<T>();
  uint32_t t = 0;
  gg::ImuWatchdog<T> w(c, t);
  ASSERT_EQ(this->feed_live(w, t, c.recovery_samples), gg::Status::kOk);
  const T a[3] = {T(0.1), T(-0.2), T(9.8)};
  const T g[3] = {T(0.01), T(0.02), T(-0.03)};
  for (int i = 1; i < c.stuck_samples; ++i) {
    t += kPeriodUs;
    EXPECT_EQ(w.on_sample(a, g, t), gg::Status::kOk) << "repeat " << i;
  }
  t += kPeriodUs;
  EXPECT_EQ(w.on_sample(a, g, t), gg::Status::kImuStuck);
  EXPECT_FALSE(w.motors_allowed());
  for (int i = 0; i < 50; ++i) {
    t += kPeriodUs;
    EXPECT_EQ(w.on_sample(a, g, t), gg::Status::kImuStuck);
  }
  EXPECT_EQ(w.faults().stuck, 1u);
  // A stuck IMU still delivers samples: it is never stale.
  EXPECT_EQ(w.poll(t + 1), gg::Status::kImuStuck);
  EXPECT_EQ(w.faults().stale, 0u);
  // Live again: recovery_samples good ones.
  EXPECT_EQ(this->feed_live(w, t, c.recovery_samples - 1), gg::Status::kImuStuck);
  EXPECT_EQ(this->feed_live(w, t, 1), gg::Status::kOk);
  // All zeros (a dead bus read as zeros) is stuck too, and counted again.
  const T z[3] = {};
  for (int i = 0; i < c.stuck_samples; ++i) w.on_sample(z, z, t += kPeriodUs);
  EXPECT_EQ(w.status(), gg::Status::kImuStuck);
  EXPECT_EQ(w.faults().stuck, 2u);
}

TYPED_TEST(ImuWatchdogTest, OneChangingChannelOfSixIsALiveSensor) {
  using T = TypeParam;
  const auto c = lsm_config<T>();
  for (int channel = 0; channel < 6; ++channel) {
    uint32_t t = 0;
    gg::ImuWatchdog<T> w(c, t);
    T a[3] = {T(0.1), T(-0.2), T(9.8)};
    T g[3] = {T(0.01), T(0.02), T(-0.03)};
    for (int i = 0; i < 4 * c.stuck_samples; ++i) {
      T& x = channel < 3 ? a[channel] : g[channel - 3];
      x = T(i % 2 ? 0.05 : -0.05);
      w.on_sample(a, g, t += kPeriodUs);
    }
    EXPECT_EQ(w.status(), gg::Status::kOk) << "channel " << channel;
    EXPECT_EQ(w.faults().stuck, 0u);
  }
}

TYPED_TEST(ImuWatchdogTest, AReadingBeyondFullScaleOrNotFiniteIsAFaultOnEveryChannel) {
  using T = TypeParam;
  const auto c = lsm_config<T>();
  const T inf = std::numeric_limits<T>::infinity();
  const T nan = std::numeric_limits<T>::quiet_NaN();
  const T accel_beyond = std::nextafter(c.accel_full_scale_mps2, inf);
  const T gyro_beyond = std::nextafter(c.gyro_full_scale_radps, inf);
  uint32_t t = 0;
  gg::ImuWatchdog<T> w(c, t);
  ASSERT_EQ(this->feed_live(w, t, c.recovery_samples), gg::Status::kOk);
  uint32_t faults = 0;
  for (int channel = 0; channel < 6; ++channel) {
    const T beyond = channel < 3 ? accel_beyond : gyro_beyond;
    const T at_scale = channel < 3 ? c.accel_full_scale_mps2 : c.gyro_full_scale_radps;
    for (T bad : {beyond, -beyond, inf, -inf, nan}) {
      T a[3], g[3];
      this->live_.next(a, g);
      (channel < 3 ? a[channel] : g[channel - 3]) = bad;
      EXPECT_EQ(w.on_sample(a, g, t += kPeriodUs), gg::Status::kImuOutOfRange)
          << "channel " << channel << " value " << bad;
      EXPECT_FALSE(w.motors_allowed());
      EXPECT_EQ(w.faults().out_of_range, ++faults);
      // Exactly full scale is a (saturated) measurement, not a fault: it starts recovery.
      this->live_.next(a, g);
      (channel < 3 ? a[channel] : g[channel - 3]) = -at_scale;
      EXPECT_EQ(w.on_sample(a, g, t += kPeriodUs), gg::Status::kImuOutOfRange);
      EXPECT_EQ(this->feed_live(w, t, c.recovery_samples - 1), gg::Status::kOk);
    }
  }
  // A run of bad samples is one fault.
  for (int i = 0; i < 5; ++i) {
    T a[3], g[3];
    this->live_.next(a, g);
    a[0] = nan;
    w.on_sample(a, g, t += kPeriodUs);
  }
  EXPECT_EQ(w.faults().out_of_range, faults + 1);
  EXPECT_EQ(w.faults().stuck + w.faults().stale, 0u);
}

TYPED_TEST(ImuWatchdogTest, AFlakyIMUKeepsTheMotorsOffInsteadOfFlickering) {
  using T = TypeParam;
  const auto c = lsm_config<T>();
  ASSERT_GT(c.recovery_samples, 2);
  uint32_t t = 0;
  gg::ImuWatchdog<T> w(c, t);
  ASSERT_EQ(this->feed_live(w, t, c.recovery_samples), gg::Status::kOk);
  int allowed = 0;
  for (int i = 0; i < 200; ++i) {
    T a[3], g[3];
    this->live_.next(a, g);
    if (i % (c.recovery_samples - 1) == 0) a[1] = std::numeric_limits<T>::quiet_NaN();
    w.on_sample(a, g, t += kPeriodUs);
    allowed += w.motors_allowed();
  }
  EXPECT_EQ(allowed, 0);
  EXPECT_GT(w.faults().out_of_range, 200u / c.recovery_samples);
}

TYPED_TEST(ImuWatchdogTest, RestartKeepsTheCountsAndWaitsForGoodSamplesAgain) {
  using T = TypeParam;
  const auto c = lsm_config<T>();
  uint32_t t = 0;
  gg::ImuWatchdog<T> w(c, t);
  ASSERT_EQ(this->feed_live(w, t, c.recovery_samples), gg::Status::kOk);
  w.poll(t += c.stale_ms * 1000u);
  ASSERT_EQ(w.faults().stale, 1u);
  w.restart(t);
  EXPECT_EQ(w.status(), gg::Status::kImuStale);
  EXPECT_EQ(w.faults().stale, 1u);
  EXPECT_EQ(this->feed_live(w, t, c.recovery_samples), gg::Status::kOk);
}

// The rule as the application will use it (docs/per-frame-layer.md, "IMU health"): every
// control loop polls the watchdog and writes the PWM only while motors_allowed(), else all
// off. Here through the device fakes at a 1 ms loop, which also measures how long after the
// last sample the motors go off when the IMU dies.
TYPED_TEST(ImuWatchdogTest, AFaultTurnsTheMotorsOffWithinTheStaleTimeOfTheLastSample) {
  using T = TypeParam;
  constexpr uint32_t kLoopUs = 1000;
  gh::FakeClock clock;
  gh::FakeImu imu(gh::ImuOutput::kSixAxis, float(kAccelFullScaleMps2), float(kGyroFullScaleRadps));
  gh::RecordingMotors motors;
  gg::ImuWatchdogConfig<T> c;
  c.accel_full_scale_mps2 = T(imu.accel_full_scale_mps2());
  c.gyro_full_scale_radps = T(imu.gyro_full_scale_radps());
  clock.set_us(0xFFFFFFFFu - 250000u);  // the IMU dies 50 ms before the clock wraps
  gg::ImuWatchdog<T> w(c, clock.now_us());
  gg::Pwm guidance;
  for (auto& d : guidance.duty) d = 200;

  LiveStream<float> live;
  uint32_t last_sample_us = clock.now_us();
  const auto loop = [&](bool imu_alive) {
    clock.advance_us(kLoopUs);
    if (imu_alive && clock.now_us() - last_sample_us >= kPeriodUs) {
      gh::ImuSample s;
      s.time_us = last_sample_us = clock.now_us();
      live.next(s.accel_mps2, s.gyro_radps);
      imu.push(s);
    }
    gh::ImuSample s;
    if (imu.read(s)) {
      const T a[3] = {T(s.accel_mps2[0]), T(s.accel_mps2[1]), T(s.accel_mps2[2])};
      const T g[3] = {T(s.gyro_radps[0]), T(s.gyro_radps[1]), T(s.gyro_radps[2])};
      w.on_sample(a, g, s.time_us);
    }
    w.poll(clock.now_us());
    motors.write(w.motors_allowed() ? guidance : gg::Pwm{});
  };

  for (int i = 0; i < 200; ++i) loop(true);
  ASSERT_FALSE(motors.all_off());
  const uint32_t death_us = clock.now_us();
  uint32_t off_after_us = 0;
  for (int i = 0; i < 1000 && !motors.all_off(); ++i) {
    loop(false);
    off_after_us = clock.now_us() - last_sample_us;
  }
  EXPECT_TRUE(motors.all_off());
  EXPECT_LT(clock.now_us(), death_us);  // the clock wrapped meanwhile
  EXPECT_EQ(w.status(), gg::Status::kImuStale);
  EXPECT_GE(off_after_us, c.stale_ms * 1000u);
  EXPECT_LE(off_after_us, c.stale_ms * 1000u + kLoopUs);
  std::printf("IMU stale -> motors off: %.1f ms after the last sample (stale %u ms, loop %u us)\n",
              off_after_us / 1000.0, unsigned(c.stale_ms), unsigned(kLoopUs));
  // Every other fault is off too, at once.
  for (int i = 0; i < 200 && !w.motors_allowed(); ++i) loop(true);
  ASSERT_FALSE(motors.all_off());
  gh::ImuSample s;
  s.time_us = clock.now_us();
  s.gyro_radps[2] = std::numeric_limits<float>::infinity();
  imu.push(s);
  gh::ImuSample r;
  ASSERT_TRUE(imu.read(r));
  const T a[3] = {T(r.accel_mps2[0]), T(r.accel_mps2[1]), T(r.accel_mps2[2])};
  const T g[3] = {T(r.gyro_radps[0]), T(r.gyro_radps[1]), T(r.gyro_radps[2])};
  EXPECT_EQ(w.on_sample(a, g, r.time_us), gg::Status::kImuOutOfRange);
  motors.write(w.motors_allowed() ? guidance : gg::Pwm{});
  EXPECT_TRUE(motors.all_off());
}

TEST(ImuStatuses, EachHasItsOwnNameAndSaysWhatToCheck) {
  const gg::Status faults[] = {gg::Status::kImuStale, gg::Status::kImuStuck,
                               gg::Status::kImuOutOfRange, gg::Status::kBadImuConfig};
  const char* names[] = {"imu_stale", "imu_stuck", "imu_out_of_range", "bad_imu_config"};
  for (int i = 0; i < 4; ++i) {
    EXPECT_STREQ(gg::status_name(faults[i]), names[i]);
    EXPECT_LT(static_cast<int>(faults[i]), gg::kStatusCount);
  }
  EXPECT_NE(std::string(gg::status_message(gg::Status::kImuStale)).find("GRASPGUIDE_IMU_STALE_MS"),
            std::string::npos);
  EXPECT_NE(std::string(gg::status_message(gg::Status::kBadImuConfig)).find("stuck_samples"),
            std::string::npos);
}

TEST(FakeButton, ReportsEachDebouncedEdgeOnceAndItsState) {
  gh::FakeButton b;
  EXPECT_EQ(b.poll(), gh::ButtonEdge::kNone);
  EXPECT_FALSE(b.down());
  b.press();
  EXPECT_EQ(b.poll(), gh::ButtonEdge::kPressed);
  EXPECT_TRUE(b.down());
  EXPECT_EQ(b.poll(), gh::ButtonEdge::kNone);
  b.press();  // already down: no second press
  EXPECT_EQ(b.poll(), gh::ButtonEdge::kNone);
  b.release();
  EXPECT_EQ(b.poll(), gh::ButtonEdge::kReleased);
  EXPECT_FALSE(b.down());
}

}  // namespace
