// Instruction counting on QEMU's mps2 boards with -icount shift=0: SysTick runs on the
// 25 MHz reference clock against a 1 GHz virtual instruction clock, so one tick is 40
// instructions. known_loop() gives a calibration of known length. Shared by the harnesses
// that count instructions (stage_counts, imu_cost).
#pragma once

#include <cstdint>

namespace stages {

struct SysTickRegs {
  volatile uint32_t csr, rvr, cvr, calib;
};
inline SysTickRegs& systick() { return *reinterpret_cast<SysTickRegs*>(uintptr_t{0xE000E010u}); }
constexpr uint32_t kTickMask = 0xFFFFFFu;

inline void start_counter() {
  systick().csr = 0;
  systick().rvr = kTickMask;
  systick().cvr = 0;
  systick().csr = 0x5u;  // processor clock, no interrupt, enabled
}

// The barrier keeps the compiler from moving work across the read.
inline uint32_t ticks() {
  __asm__ volatile("" ::: "memory");
  const uint32_t v = systick().cvr;
  __asm__ volatile("" ::: "memory");
  return v;
}
inline int32_t elapsed(uint32_t from, uint32_t to) { return int32_t((from - to) & kTickMask); }

// Exactly 2 * n instructions (subs + bne per iteration) plus a constant.
__attribute__((noinline)) inline void known_loop(uint32_t n) {
  __asm__ volatile("1: subs %0, %0, #1\n bne 1b" : "+r"(n) : : "cc");
}

}  // namespace stages
