// The hardware a GraspGuide device needs, as small interfaces: each board implements them
// (src/boards/, promini/), tests use the fakes in fake_hal.h, the simulated device a POSIX
// layer. Both device libraries take the same ones. C++14 with <stddef.h> and <stdint.h>
// only, so an 8-bit AVR board implements them as a host does.
#pragma once

#include <stddef.h>
#include <stdint.h>

#include "graspguide_cue/pwm.h"

namespace graspguide {
namespace hal {

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

// What an Imu's sample holds.
enum class ImuOutput : uint8_t {
  // A 6-axis part (accelerometer + gyroscope): accel_mps2 is the specific force, gravity plus
  // the hand's own acceleration; the device estimates gravity from both channels.
  kSixAxis,
  // A part with on-chip fusion (BNO055 class): accel_mps2 is the chip's gravity estimate,
  // already separated from the hand's acceleration, and gyro_radps its calibrated rate.
  kFusedGravity,
};

// One reading in the IMU's own axes (the board declares how they sit on the hand).
struct ImuSample {
  uint32_t time_us = 0;  // the Clock's time when it was read
  float accel_mps2[3] = {};
  float gyro_radps[3] = {};
};

// An inertial sensor, polled. read() never blocks for long (one bus transfer) and returns
// false when the part has no new sample since the last call, or the transfer failed; the
// health rule (graspguide_cue/imu_watchdog.h) turns a long silence into a fault.
class Imu {
 public:
  virtual ImuOutput output() const = 0;
  virtual bool read(ImuSample& out) = 0;
  // The ranges the part was set to: no healthy reading exceeds them.
  virtual float accel_full_scale_mps2() const = 0;
  virtual float gyro_full_scale_radps() const = 0;

 protected:
  ~Imu() = default;
};

// A debounced edge of a Button, at most one per poll.
enum class ButtonEdge : uint8_t { kNone, kPressed, kReleased };

// A push button, debounced by the implementation (a contact bounces for a few ms; each
// bounce must not start a trial). poll() is called every control loop.
class Button {
 public:
  virtual ButtonEdge poll() = 0;
  // The debounced state after the last poll: true while held down.
  virtual bool down() const = 0;

 protected:
  ~Button() = default;
};

}  // namespace hal
}  // namespace graspguide
