#include "cortex_m_hal.h"

extern "C" {
volatile uint32_t m4f_pwm_ccr[graspguide::kMaxContacts];
volatile uint32_t m4f_ms;
void SysTick_Handler(void) { m4f_ms = m4f_ms + 1; }
}

namespace graspguide::m4f {
namespace {

struct SysTickRegs {
  volatile uint32_t csr, rvr, cvr, calib;
};
SysTickRegs& systick() { return *reinterpret_cast<SysTickRegs*>(uintptr_t{0xE000E010u}); }
volatile uint32_t& scb_icsr() {
  return *reinterpret_cast<volatile uint32_t*>(uintptr_t{0xE000ED04u});
}
constexpr uint32_t kPendStSet = 1u << 26;

constexpr uint32_t kTicksPerMs = M4F_CORE_HZ / 1000u;
constexpr uint32_t kTicksPerUs = M4F_CORE_HZ / 1000000u;
static_assert(kTicksPerUs >= 1 && kTicksPerMs - 1 <= 0xFFFFFFu, "SysTick reload is 24-bit");

}  // namespace

void SysTickClock::start() {
  systick().csr = 0;
  systick().rvr = kTicksPerMs - 1;
  systick().cvr = 0;
  systick().csr = 0x7u;  // processor clock, interrupt, enable
}

uint32_t SysTickClock::now_us() {
  // With interrupts masked, a reload not yet counted by the interrupt shows as a pending
  // SysTick: count that millisecond and re-read the counter.
  uint32_t primask;
  __asm volatile("mrs %0, primask\n cpsid i" : "=r"(primask)::"memory");
  uint32_t ms = m4f_ms;
  uint32_t cvr = systick().cvr;
  if (scb_icsr() & kPendStSet) {
    cvr = systick().cvr;
    ++ms;
  }
  __asm volatile("msr primask, %0" ::"r"(primask) : "memory");
  return ms * 1000u + (kTicksPerMs - 1 - cvr) / kTicksPerUs;
}

}  // namespace graspguide::m4f
