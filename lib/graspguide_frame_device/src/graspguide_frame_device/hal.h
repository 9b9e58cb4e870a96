// What the device needs from a board, as three small interfaces: the sketch implements them
// over its UART, PWM pins and micros(); tests use in-memory fakes.
#pragma once

#include <stddef.h>
#include <stdint.h>

#include "graspguide_frame/pwm.h"

namespace graspguide_frame_device {

// A serial link. read/write never block; they return how many bytes they moved.
class ByteStream {
 public:
  virtual size_t read(uint8_t* buffer, size_t capacity) = 0;
  virtual size_t write(const uint8_t* data, size_t length) = 0;

 protected:
  ~ByteStream() = default;
};

// All motors are written together, so a frame never shows half old, half new PWM.
class Motors {
 public:
  virtual void write(const graspguide::Pwm& pwm) = 0;

 protected:
  ~Motors() = default;
};

// Monotonic microseconds; wraps after ~71 minutes, so compare with unsigned subtraction.
class Clock {
 public:
  virtual uint32_t now_us() = 0;

 protected:
  ~Clock() = default;
};

}  // namespace graspguide_frame_device
