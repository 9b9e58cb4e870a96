// The hardware interfaces of the bare-metal Cortex-M images (src/harness/size/ and
// src/boards/mps2_an386/): a SysTick clock and four register-like motor outputs. Only
// architectural (ARMv7-M) registers, so no vendor headers.
#pragma once

#include <cstdint>

#include "graspguide_hal/hal.h"

#ifndef M4F_CORE_HZ
#define M4F_CORE_HZ 25000000u  // SysTick source clock (25 MHz on QEMU's mps2 boards)
#endif

extern "C" {
// Stand-in for a timer's four capture/compare registers, one per motor; a debugger or
// QEMU's monitor reads them.
extern volatile uint32_t m4f_pwm_ccr[graspguide::kMaxContacts];
extern volatile uint32_t m4f_ms;  // SysTick interrupts since start
void SysTick_Handler(void);
}

namespace graspguide::m4f {

// 1 kHz SysTick interrupt plus the down-counter for the microseconds within the tick.
// The interrupt also wakes an idle loop once a millisecond, so the POSE watchdog runs
// even when the line is silent.
class SysTickClock final : public graspguide::hal::Clock {
 public:
  void start();
  uint32_t now_us() override;
};

// All motors written together, like a timer's CCR1..CCR4.
class RegisterMotors final : public graspguide::hal::MotorOutputs {
 public:
  void write(const Pwm& pwm) override {
    for (int i = 0; i < kMaxContacts; ++i) m4f_pwm_ccr[i] = pwm.duty[i];
  }
};

}  // namespace graspguide::m4f
