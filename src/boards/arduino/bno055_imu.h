// The fused-chip path: a Bosch BNO055 through Adafruit's BNO055 library (lib_deps
// adafruit/Adafruit BNO055). The chip fuses its accelerometer and gyroscope itself and gives
// the gravity vector in its own axes; the device uses that instead of its estimator.
#pragma once

#include <Adafruit_BNO055.h>
#include <Arduino.h>

#include "polled_imu.h"

namespace graspguide::board {

class Bno055Imu final : public PolledImu {
 public:
  Bno055Imu(graspguide::hal::Clock& clock, uint32_t period_us) : PolledImu(clock, period_us) {}

  // IMUPLUS: accelerometer and gyroscope fusion without the magnetometer, whose yaw the
  // guidance does not need and whose disturbances (motors, metal) would only add error.
  bool begin() {
    if (!part_.begin(OPERATION_MODE_IMUPLUS)) return false;
    part_.setExtCrystalUse(true);  // the Adafruit breakout's 32 kHz crystal: steadier timing
    started();
    return true;
  }

  graspguide::hal::ImuOutput output() const override {
    return graspguide::hal::ImuOutput::kFusedGravity;
  }
  // The chip's power-on ranges, which IMUPLUS keeps: +-4 g and +-2000 dps. Its gravity
  // vector's magnitude never exceeds the accelerometer's range.
  float accel_full_scale_mps2() const override { return 4.0f * kStandardGravity_mps2; }
  float gyro_full_scale_radps() const override { return 2000.0f * kRadPerDeg; }

  // Gravity and the calibrated rate: the rate keeps the stuck rule meaningful while the
  // hand rests, when the fused gravity alone may hold its 0.01 m/s^2 step for a while.
  bool read(graspguide::hal::ImuSample& out) override {
    uint32_t now_us = 0;
    if (!due(now_us)) return false;
    sensors_event_t gravity, gyro;
    if (!part_.getEvent(&gravity, Adafruit_BNO055::VECTOR_GRAVITY)) return false;
    if (!part_.getEvent(&gyro, Adafruit_BNO055::VECTOR_GYROSCOPE)) return false;
    fill(now_us, gravity, gyro, out);
    return true;
  }

 private:
  Adafruit_BNO055 part_;
};

}  // namespace graspguide::board
