/* Runs an ATmega328P ELF under libsimavr at 8 MHz and gives it three byte-wide channels
 * through general-purpose I/O registers, so a harness needs no UART model and its
 * measured code is disturbed by nothing but one `out` instruction per mark:
 *   GPIOR2 read  -> the next byte of stdin (0xFF after end of input, and a flag)
 *   GPIOR1 write -> one byte to stdout
 *   GPIOR0 write -> 1 starts a cycle count, 2 prints the cycles since the last start
 * The program ends when the AVR sleeps with interrupts off.
 *   simavr_runner FIRMWARE.elf [MAX_CYCLES]
 * Exit status: 0 done; 2 bad use or the ELF cannot be loaded; 3 the AVR crashed;
 * 4 the cycle budget ran out (a hang); 5 the AVR read past the end of stdin.
 */
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_io.h>

/* Data-space addresses (I/O address + 0x20) of GPIOR0..2 on the ATmega328P. */
enum { kMarkReg = 0x3E, kOutReg = 0x4A, kInReg = 0x4B };
enum { kStartMark = 1, kStopMark = 2 };

static avr_cycle_count_t g_start;
static int g_read_past_end;

static void on_mark(avr_t* avr, avr_io_addr_t addr, uint8_t v, void* param) {
  (void)addr;
  (void)param;
  if (v == kStartMark) {
    g_start = avr->cycle;
  } else if (v == kStopMark) {
    printf("%llu", (unsigned long long)(avr->cycle - g_start));
  }
}

static void on_out(avr_t* avr, avr_io_addr_t addr, uint8_t v, void* param) {
  (void)avr;
  (void)addr;
  (void)param;
  putchar(v);
}

static uint8_t on_in(avr_t* avr, avr_io_addr_t addr, void* param) {
  (void)avr;
  (void)addr;
  (void)param;
  const int c = getchar();
  if (c == EOF) {
    g_read_past_end = 1;
    return 0xFF;
  }
  return (uint8_t)c;
}

/* stdout carries the harness's bytes only: simavr's own messages go to stderr, and its
 * chatter ("Loaded 8764 .text ...") nowhere. */
static void log_to_stderr(avr_t* avr, const int level, const char* format, va_list ap) {
  (void)avr;
  if (level <= LOG_WARNING) vfprintf(stderr, format, ap);
}

int main(int argc, char** argv) {
  if (argc < 2 || argc > 3) {
    fprintf(stderr, "usage: %s FIRMWARE.elf [MAX_CYCLES]\n", argv[0]);
    return 2;
  }
  const unsigned long long max_cycles = argc == 3 ? strtoull(argv[2], NULL, 10) : 4000000000ull;
  avr_global_logger_set(log_to_stderr);
  static elf_firmware_t fw;
  if (elf_read_firmware(argv[1], &fw) != 0) {
    fprintf(stderr, "simavr_runner: cannot read %s\n", argv[1]);
    return 2;
  }
  avr_t* avr = avr_make_mcu_by_name("atmega328p");
  if (!avr) {
    fprintf(stderr, "simavr_runner: this simavr has no atmega328p\n");
    return 2;
  }
  avr_init(avr);
  avr_load_firmware(avr, &fw);
  avr->frequency = 8000000;
  avr_register_io_write(avr, kMarkReg, on_mark, NULL);
  avr_register_io_write(avr, kOutReg, on_out, NULL);
  avr_register_io_read(avr, kInReg, on_in, NULL);

  int state = cpu_Running;
  while (state != cpu_Done && state != cpu_Crashed && avr->cycle < max_cycles) state = avr_run(avr);
  fflush(stdout);
  if (state == cpu_Crashed) {
    fprintf(stderr, "simavr_runner: the AVR crashed at cycle %llu\n",
            (unsigned long long)avr->cycle);
    return 3;
  }
  if (state != cpu_Done) {
    fprintf(stderr, "simavr_runner: still running after %llu cycles\n", max_cycles);
    return 4;
  }
  if (g_read_past_end) {
    fprintf(stderr, "simavr_runner: the AVR read past the end of its input\n");
    return 5;
  }
  return 0;
}
