// GraspGuide: the device firmware on QEMU's mps2-an386 (Cortex-M4F). The same
// Application and LinkDevice as every board, over the board's CMSDK UART0, which QEMU
// connects to a host pseudo-terminal with -serial pty; the host tools drive it like a
// wearable on a serial port. Motors are four register words (no PWM peripheral on this
// board model); time is SysTick. Start-up, runtime stubs (trapping malloc), linker
// script and HAL are src/platform/cortex_m/'s.
#include <cstdint>

#include "cmsdk_uart.h"
#include "cortex_m_hal.h"
#include "graspguide_device/link_device.h"

// Only sets the divisor: QEMU moves the bytes as fast as the pty takes them.
#ifndef M4F_UART_BAUD
#define M4F_UART_BAUD 115200u
#endif
#ifndef GRASPGUIDE_BUILD_ID
#define GRASPGUIDE_BUILD_ID 0
#endif

namespace gg = graspguide;
namespace dev = graspguide::device;

extern "C" {
// The UART's losses (CmsdkUart::rx_dropped, tx_frames_dropped), published for a debugger
// or the QEMU test: the link has no message for them.
volatile uint32_t m4f_uart_rx_dropped;
volatile uint32_t m4f_uart_tx_frames_dropped;
volatile uint32_t m4f_stack_peak;     // bytes of stack ever used (painted by start-up)
uint32_t m4f_stack_high_water(void);  // startup.c

// startup.c's flash vector table, whose 16 system entries are copied to the RAM table.
typedef void (*m4f_vector_t)(void);
extern const m4f_vector_t m4f_vectors[];
void Default_Handler(void);

void m4f_uart0_rx_handler(void);
void m4f_uart0_tx_handler(void);
}

namespace {

// mps2-an386 (AN386 application note; QEMU hw/arm/mps2.c): UART0 at 0x40004000, its RX
// interrupt on IRQ 0 and TX on IRQ 1; the NVIC has 32 external interrupts.
constexpr uintptr_t kUart0Base = 0x40004000u;
constexpr int kUart0RxIrq = 0;
constexpr int kUart0TxIrq = 1;
constexpr int kIrqCount = 32;

volatile uint32_t& scb_vtor() {
  return *reinterpret_cast<volatile uint32_t*>(uintptr_t{0xE000ED08u});
}
volatile uint32_t& nvic_iser0() {
  return *reinterpret_cast<volatile uint32_t*>(uintptr_t{0xE000E100u});
}

dev::DeviceInfo board_info() {
  dev::DeviceInfo info;
  info.board = "qemu-mps2-an386";
  info.build_id = GRASPGUIDE_BUILD_ID;
  return info;
}

// Defined in this order on purpose: each object takes references to the ones above it,
// and dynamic initialisation runs in definition order (Application's constructor writes
// the motors off before main).
gg::m4f::CmsdkUart g_uart(kUart0Base, M4F_CORE_HZ);
gg::m4f::SysTickClock g_clock;
gg::m4f::RegisterMotors g_motors;
dev::Application g_app(g_motors, g_clock);
dev::LinkDevice g_link(g_uart, g_app, board_info());

// startup.c's table sends every external interrupt to Default_Handler and is in flash,
// which stays shared with the other Cortex-M images; this board's handlers go into a RAM
// copy instead. VTOR wants the table aligned to its size rounded up to a power of two.
constexpr int kVectorCount = 16 + kIrqCount;
alignas(256) m4f_vector_t g_ram_vectors[kVectorCount];
static_assert(sizeof g_ram_vectors <= 256, "raise the alignment with the table size");

void install_vectors() {
  for (int i = 0; i < 16; ++i) g_ram_vectors[i] = m4f_vectors[i];
  for (int i = 16; i < kVectorCount; ++i) g_ram_vectors[i] = Default_Handler;
  g_ram_vectors[16 + kUart0RxIrq] = m4f_uart0_rx_handler;
  g_ram_vectors[16 + kUart0TxIrq] = m4f_uart0_tx_handler;
  __asm volatile("dsb" ::: "memory");
  scb_vtor() = uint32_t(reinterpret_cast<uintptr_t>(g_ram_vectors));
  __asm volatile("dsb\n isb" ::: "memory");
}

}  // namespace

extern "C" void m4f_uart0_rx_handler(void) { g_uart.on_rx_irq(); }
extern "C" void m4f_uart0_tx_handler(void) { g_uart.on_tx_irq(); }

int main() {
  install_vectors();
  g_clock.start();
  g_uart.start(M4F_UART_BAUD);
  nvic_iser0() = (1u << kUart0RxIrq) | (1u << kUart0TxIrq);
  uint32_t stack_scanned_ms = 0;
  for (;;) {
    g_link.poll();
    m4f_uart_rx_dropped = g_uart.rx_dropped();
    m4f_uart_tx_frames_dropped = g_uart.tx_frames_dropped();
    // The scan reads the whole painted region, so only every 100 ms.
    if (m4f_ms - stack_scanned_ms >= 100u) {
      stack_scanned_ms = m4f_ms;
      m4f_stack_peak = m4f_stack_high_water();
    }
    // Sleep until the next interrupt (a byte, or the 1 ms tick) unless bytes arrived
    // while poll() was busy. Masked, so a byte landing between the check and the WFI
    // still wakes it (a pending interrupt ends WFI even with PRIMASK set).
    __asm volatile("cpsid i" ::: "memory");
    if (!g_uart.rx_pending()) __asm volatile("wfi" ::: "memory");
    __asm volatile("cpsie i" ::: "memory");
  }
}
