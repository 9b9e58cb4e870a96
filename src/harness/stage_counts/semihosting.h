// Just the two semihosting calls the stage counter needs: write a string to QEMU's stdout
// and exit with a status. newlib's rdimon would also do it, but its stdio allocates a
// buffer through malloc, which traps here by design (src/platform/cortex_m/syscalls.cpp).
#pragma once

#include <cstdint>

namespace stages {

inline uint32_t semihost_call(uint32_t op, const void* arg) {
  register uint32_t r0 __asm__("r0") = op;
  register const void* r1 __asm__("r1") = arg;
  __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
  return r0;
}

constexpr uint32_t kSysWrite0 = 0x04;
constexpr uint32_t kSysExitExtended = 0x20;
constexpr uint32_t kAdpStoppedApplicationExit = 0x20026;

inline void write0(const char* text) { semihost_call(kSysWrite0, text); }

[[noreturn]] inline void exit(int code) {
  const uint32_t block[2] = {kAdpStoppedApplicationExit, uint32_t(code)};
  semihost_call(kSysExitExtended, block);
  for (;;) {
  }
}

}  // namespace stages
