// In-memory hardware for tests and host tools: a clock set by hand, motors that record
// every write.
#pragma once

#include "graspguide_device/hal.h"

namespace graspguide::device {

class FakeClock final : public Clock {
 public:
  uint32_t now_us() override { return now_us_; }
  void set_us(uint32_t t) { now_us_ = t; }
  void advance_us(uint32_t dt) { now_us_ += dt; }

 private:
  uint32_t now_us_ = 0;
};

class RecordingMotors final : public MotorOutputs {
 public:
  void write(const Pwm& pwm) override {
    last_ = pwm;
    ++writes_;
  }
  const Pwm& last() const { return last_; }
  bool all_off() const {
    for (uint8_t d : last_.duty)
      if (d != 0) return false;
    return true;
  }
  uint32_t writes() const { return writes_; }

 private:
  Pwm last_;
  uint32_t writes_ = 0;
};

}  // namespace graspguide::device
