// The hardware the application needs, as three small interfaces. Each board implements
// them (src/), tests use the fakes in fake_hal.h, the simulated device a POSIX layer.
#pragma once

#include <cstddef>
#include <cstdint>

#include "graspguide/types.h"

namespace graspguide::device {

// All motors are written together, so a frame never shows half old, half new PWM.
class MotorOutputs {
 public:
  virtual void write(const Pwm& pwm) = 0;

 protected:
  ~MotorOutputs() = default;
};

// Monotonic microseconds; wraps after ~71 minutes, so compare with unsigned subtraction.
class Clock {
 public:
  virtual uint32_t now_us() = 0;

 protected:
  ~Clock() = default;
};

// A serial link. read/write never block; they return how many bytes they moved.
class ByteStream {
 public:
  virtual size_t read(uint8_t* buffer, size_t capacity) = 0;
  virtual size_t write(const uint8_t* data, size_t length) = 0;

 protected:
  ~ByteStream() = default;
};

}  // namespace graspguide::device
