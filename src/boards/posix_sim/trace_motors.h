// Motor outputs of the simulated device: kept in memory and, optionally, appended to a
// CSV trace (time, four PWM values) on every change, flushed so nothing is lost on a kill.
#pragma once

#include <cstdio>

#include "graspguide_hal/hal.h"

namespace graspguide::sim {

class TraceMotors final : public graspguide::hal::MotorOutputs {
 public:
  TraceMotors(graspguide::hal::Clock& clock, FILE* trace) : clock_(clock), trace_(trace) {
    if (trace_) std::fprintf(trace_, "device_time_us,pwm0,pwm1,pwm2,pwm3\n");
  }

  void write(const Pwm& pwm) override {
    const bool changed = !written_ || !same(pwm, last_);
    last_ = pwm;
    written_ = true;
    if (trace_ && changed) {
      std::fprintf(trace_, "%u,%u,%u,%u,%u\n", clock_.now_us(), pwm.duty[0], pwm.duty[1],
                   pwm.duty[2], pwm.duty[3]);
      std::fflush(trace_);
    }
  }

  const Pwm& last() const { return last_; }

 private:
  static bool same(const Pwm& a, const Pwm& b) {
    for (int i = 0; i < kMaxContacts; ++i)
      if (a.duty[i] != b.duty[i]) return false;
    return true;
  }

  graspguide::hal::Clock& clock_;
  FILE* trace_;
  Pwm last_;
  bool written_ = false;
};

}  // namespace graspguide::sim
