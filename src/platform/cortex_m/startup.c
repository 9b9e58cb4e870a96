/* GraspGuide: bare-metal start-up for a generic Cortex-M4F (no vendor headers).
 * Vector table, Reset_Handler (FPU on, .data copied, .bss zeroed, static constructors,
 * main, _exit), default handlers and a stack high-water mark. Only core (SCB)
 * registers are touched. */
#include <stdint.h>

extern uint32_t _estack, _sidata, _sdata, _edata, _sbss, _ebss;
extern void (*__preinit_array_start[])(void);
extern void (*__preinit_array_end[])(void);
extern void (*__init_array_start[])(void);
extern void (*__init_array_end[])(void);

#define M4F_STACK_PAINT 0xA5A5A5A5u

int main(void);
uint32_t m4f_stack_high_water(void);
void _exit(int status) __attribute__((noreturn));
void m4f_reset_continue(void) __attribute__((noreturn, used));

void Reset_Handler(void) __attribute__((naked, noreturn));
void Default_Handler(void);

/* Weak aliases: a board or test overrides only what it uses. */
#define WEAK_HANDLER(name) void name(void) __attribute__((weak, alias("Default_Handler")))
WEAK_HANDLER(NMI_Handler);
WEAK_HANDLER(HardFault_Handler);
WEAK_HANDLER(MemManage_Handler);
WEAK_HANDLER(BusFault_Handler);
WEAK_HANDLER(UsageFault_Handler);
WEAK_HANDLER(SVC_Handler);
WEAK_HANDLER(DebugMon_Handler);
WEAK_HANDLER(PendSV_Handler);
WEAK_HANDLER(SysTick_Handler);

/* 16 system exceptions + 32 external interrupts, all unused by the harness. */
#define M4F_IRQ_COUNT 32
typedef void (*vector_t)(void);
__attribute__((section(".isr_vector"), used)) const vector_t m4f_vectors[16 + M4F_IRQ_COUNT] = {
    (vector_t)(uintptr_t)&_estack,
    Reset_Handler,
    NMI_Handler,
    HardFault_Handler,
    MemManage_Handler,
    BusFault_Handler,
    UsageFault_Handler,
    0,
    0,
    0,
    0, /* reserved */
    SVC_Handler,
    DebugMon_Handler,
    0, /* reserved */
    PendSV_Handler,
    SysTick_Handler,
    [16 ... 16 + M4F_IRQ_COUNT - 1] = Default_Handler,
};

/* Naked and written in assembly so that no compiler-generated FPU instruction can run
 * before CPACR grants access to CP10/CP11 (the single-precision FPU). */
void Reset_Handler(void) {
  __asm volatile(
      "ldr   sp, =_estack       \n" /* also right when a debugger jumps here */
      "ldr   r0, =0xE000ED88    \n" /* SCB->CPACR */
      "ldr   r1, [r0]           \n"
      "orr   r1, r1, #(0xF << 20)\n" /* CP10, CP11: full access */
      "str   r1, [r0]           \n"
      "dsb                      \n"
      "isb                      \n"
      "b     m4f_reset_continue \n");
}

void m4f_reset_continue(void) {
  /* volatile: keep these loops from turning into memcpy/memset calls before .data
   * and .bss exist (harmless with newlib, but the start-up stays self-contained). */
  volatile uint32_t* src = &_sidata;
  volatile uint32_t* dst = &_sdata;
  while (dst < &_edata) *dst++ = *src++;
  for (dst = &_sbss; dst < &_ebss;) *dst++ = 0u;

  /* Paint the free RAM up to just below this frame, so m4f_stack_high_water() can
   * tell how deep the stack has ever been. */
  uint32_t sp;
  __asm volatile("mov %0, sp" : "=r"(sp));
  for (dst = &_ebss; (uintptr_t)dst < sp - 64u;) *dst++ = M4F_STACK_PAINT;

  for (void (**f)(void) = __preinit_array_start; f < __preinit_array_end; ++f) (*f)();
  for (void (**f)(void) = __init_array_start; f < __init_array_end; ++f) (*f)();

  _exit(main());
}

uint32_t m4f_stack_high_water(void) {
  const uint32_t* p = &_ebss;
  while (p < &_estack && *p == M4F_STACK_PAINT) ++p;
  return (uint32_t)((uintptr_t)&_estack - (uintptr_t)p);
}

void Default_Handler(void) {
  for (;;) {
  }
}
