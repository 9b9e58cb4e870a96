// The harness's link to simavr_runner (simavr_runner/runner.c): bytes in and out and the
// cycle marks through general-purpose I/O registers, so a measured region is disturbed by
// one `out` instruction at each end and nothing else (no UART, no interrupts).
#pragma once

#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <stdint.h>
#include <string.h>

namespace channel {

inline uint8_t read_byte() { return GPIOR2; }

inline void read_bytes(void* out, uint8_t n) {
  uint8_t* p = static_cast<uint8_t*>(out);
  for (uint8_t i = 0; i < n; ++i) p[i] = read_byte();
}

// Little-endian, as the AVR and the host both are.
template <typename V>
inline V read() {
  V v;
  read_bytes(&v, sizeof v);
  return v;
}

inline void put(char c) { GPIOR1 = static_cast<uint8_t>(c); }

inline void put(const char* s) {
  while (*s) put(*s++);
}

inline void put_hex(uint32_t v, uint8_t digits) {
  for (int8_t i = static_cast<int8_t>(digits) - 1; i >= 0; --i) {
    const uint8_t d = (v >> (4 * i)) & 0xF;
    put(static_cast<char>(d < 10 ? '0' + d : 'a' + d - 10));
  }
}

// The float's bits: the host reads the exact value.
inline void put_float(float f) {
  uint32_t bits;
  memcpy(&bits, &f, sizeof bits);
  put_hex(bits, 8);
}

inline void put_uint(uint32_t v) {
  char buf[11];
  uint8_t n = 0;
  do {
    buf[n++] = static_cast<char>('0' + v % 10);
    v /= 10;
  } while (v);
  while (n) put(buf[--n]);
}

// The memory clobbers keep the compiler from moving the measured work across a mark.
inline void start_count() {
  asm volatile("" ::: "memory");
  GPIOR0 = 1;
  asm volatile("" ::: "memory");
}

// The runner prints the cycles since start_count() here, in decimal.
inline void stop_count() {
  asm volatile("" ::: "memory");
  GPIOR0 = 2;
  asm volatile("" ::: "memory");
}

// The stack's high-water mark: paint() fills the free RAM between the static data and the
// stack with a pattern at start-up, stack_used() finds how far down the stack reached.
extern "C" uint8_t __heap_start;  // avr-libc's linker script: the end of .bss
constexpr uint8_t kPaint = 0xC5;

inline void paint() {
  uint8_t* p = &__heap_start;
  uint8_t* const top = reinterpret_cast<uint8_t*>(SP) - 8;  // below main's own frame
  while (p < top) *p++ = kPaint;
}

inline uint16_t stack_used() {
  const uint8_t* p = &__heap_start;
  while (p <= reinterpret_cast<const uint8_t*>(RAMEND) && *p == kPaint) ++p;
  return static_cast<uint16_t>(RAMEND + 1 - reinterpret_cast<uintptr_t>(p));
}

// Sleep with interrupts off: simavr ends the run.
[[noreturn]] inline void halt() {
  cli();
  set_sleep_mode(SLEEP_MODE_PWR_DOWN);
  sleep_enable();
  for (;;) sleep_cpu();
}

}  // namespace channel
