// The 6-axis IMU path: an ST LSM6DSOX through Adafruit's LSM6DS library (lib_deps
// adafruit/Adafruit LSM6DS). The part is in production, on a STEMMA QT breakout that plugs
// into the Feather without soldering, and the library is Adafruit's maintained driver for it.
#pragma once

#include <Adafruit_LSM6DSOX.h>
#include <Arduino.h>

#include "graspguide_device/hal.h"

namespace graspguide::board {

class Lsm6dsoxImu final : public device::Imu {
 public:
  Lsm6dsoxImu(device::Clock& clock, uint32_t period_us) : clock_(clock), period_us_(period_us) {}

  // False when no part answers at the default address: read() then never has a sample.
  bool begin() {
    if (!part_.begin_I2C()) return false;
    // +-8 g: gravity plus a moving hand's acceleration without clipping; +-2000 dps: far
    // above a guided hand's rotation (the virtual participant turns at up to 90 deg/s).
    part_.setAccelRange(LSM6DS_ACCEL_RANGE_8_G);
    part_.setGyroRange(LSM6DS_GYRO_RANGE_2000_DPS);
    part_.setAccelDataRate(LSM6DS_RATE_104_HZ);
    part_.setGyroDataRate(LSM6DS_RATE_104_HZ);
    started_ = true;
    last_read_us_ = clock_.now_us() - period_us_;
    return true;
  }

  device::ImuOutput output() const override { return device::ImuOutput::kSixAxis; }
  float accel_full_scale_mps2() const override { return 8.0f * kStandardGravity_mps2; }
  // The nominal range; the part reports up to 2,294 dps in its over-range band, which counts
  // as out of range here and which no guided hand reaches.
  float gyro_full_scale_radps() const override { return 2000.0f * kRadPerDeg; }

  bool read(device::ImuSample& out) override {
    if (!started_) return false;
    const uint32_t now_us = clock_.now_us();
    if (static_cast<int32_t>(now_us - last_read_us_) < static_cast<int32_t>(period_us_))
      return false;
    last_read_us_ = now_us;
    sensors_event_t accel, gyro, temp;
    if (!part_.getEvent(&accel, &gyro, &temp)) return false;
    out.time_us = now_us;
    out.accel_mps2[0] = accel.acceleration.x;
    out.accel_mps2[1] = accel.acceleration.y;
    out.accel_mps2[2] = accel.acceleration.z;
    out.gyro_radps[0] = gyro.gyro.x;
    out.gyro_radps[1] = gyro.gyro.y;
    out.gyro_radps[2] = gyro.gyro.z;
    return true;
  }

 private:
  static constexpr float kStandardGravity_mps2 = 9.80665f;
  static constexpr float kRadPerDeg = 0.0174532925f;

  device::Clock& clock_;
  uint32_t period_us_;
  uint32_t last_read_us_ = 0;
  bool started_ = false;
  Adafruit_LSM6DSOX part_;
};

}  // namespace graspguide::board
