// What the Arduino IMU drivers share: reading at a fixed period from the board clock
// (across its wrap), and a sample from the Adafruit unified-sensor events they all return.
#pragma once

#include <Adafruit_Sensor.h>

#include "graspguide_hal/hal.h"

namespace graspguide::board {

class PolledImu : public graspguide::hal::Imu {
 protected:
  static constexpr float kStandardGravity_mps2 = 9.80665f;
  static constexpr float kRadPerDeg = 0.0174532925f;

  PolledImu(graspguide::hal::Clock& clock, uint32_t period_us)
      : clock_(clock), period_us_(period_us) {}

  // The first read() is due at once.
  void started() {
    started_ = true;
    last_read_us_ = clock_.now_us() - period_us_;
  }

  // True, with the time in now_us, when a period has passed since the last read.
  bool due(uint32_t& now_us) {
    if (!started_) return false;
    now_us = clock_.now_us();
    if (static_cast<int32_t>(now_us - last_read_us_) < static_cast<int32_t>(period_us_))
      return false;
    last_read_us_ = now_us;
    return true;
  }

  static void fill(uint32_t now_us, const sensors_event_t& accel, const sensors_event_t& gyro,
                   graspguide::hal::ImuSample& out) {
    out.time_us = now_us;
    out.accel_mps2[0] = accel.acceleration.x;
    out.accel_mps2[1] = accel.acceleration.y;
    out.accel_mps2[2] = accel.acceleration.z;
    out.gyro_radps[0] = gyro.gyro.x;
    out.gyro_radps[1] = gyro.gyro.y;
    out.gyro_radps[2] = gyro.gyro.z;
  }

 private:
  graspguide::hal::Clock& clock_;
  uint32_t period_us_;
  uint32_t last_read_us_ = 0;
  bool started_ = false;
};

}  // namespace graspguide::board
