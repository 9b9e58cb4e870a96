// The 6-axis IMU path: an ST LSM6DSOX through Adafruit's LSM6DS library (lib_deps
// adafruit/Adafruit LSM6DS). The part is in production, on a STEMMA QT breakout that plugs
// into the Feather without soldering, and the library is Adafruit's maintained driver for it.
#pragma once

#include <Adafruit_LSM6DSOX.h>
#include <Arduino.h>

#include "polled_imu.h"

namespace graspguide::board {

class Lsm6dsoxImu final : public PolledImu {
 public:
  Lsm6dsoxImu(graspguide::hal::Clock& clock, uint32_t period_us) : PolledImu(clock, period_us) {}

  // False when no part answers at the default address: read() then never has a sample.
  bool begin() {
    if (!part_.begin_I2C()) return false;
    // +-8 g: gravity plus a moving hand's acceleration without clipping; +-2000 dps: far
    // above a guided hand's rotation (the virtual participant turns at up to 90 deg/s).
    part_.setAccelRange(LSM6DS_ACCEL_RANGE_8_G);
    part_.setGyroRange(LSM6DS_GYRO_RANGE_2000_DPS);
    part_.setAccelDataRate(LSM6DS_RATE_104_HZ);
    part_.setGyroDataRate(LSM6DS_RATE_104_HZ);
    started();
    return true;
  }

  graspguide::hal::ImuOutput output() const override {
    return graspguide::hal::ImuOutput::kSixAxis;
  }
  float accel_full_scale_mps2() const override { return 8.0f * kStandardGravity_mps2; }
  // The nominal range; the part reports up to 2,294 dps in its over-range band, which counts
  // as out of range here and which no guided hand reaches.
  float gyro_full_scale_radps() const override { return 2000.0f * kRadPerDeg; }

  bool read(graspguide::hal::ImuSample& out) override {
    uint32_t now_us = 0;
    if (!due(now_us)) return false;
    sensors_event_t accel, gyro, temp;
    if (!part_.getEvent(&accel, &gyro, &temp)) return false;
    fill(now_us, accel, gyro, out);
    return true;
  }

 private:
  Adafruit_LSM6DSOX part_;
};

}  // namespace graspguide::board
