/* Runs a Pro Mini (ATmega328P, 8 MHz) ELF under libsimavr with UART0 on a host
 * pseudo-terminal, for `--port promini-sim`, and records the motor PWM from the timers.
 *
 *   promini_sim_runner FIRMWARE.elf [--trace FILE.csv] [--motors OC2B,OC1A,OC1B,OC2A]
 *                      [--marks FILE] [--stats FILE] [--fast] [--max-cycles N]
 *
 * stdout: one line "GRASPGUIDE_SIM_PTY <path>" once the pty is open (as the simulated
 * device prints), nothing else.
 * --motors: default OC2B,OC1A,OC1B,OC2A, the sketch's pins 3, 9, 10, 11
 *   (promini/GraspGuideProMini/board_glue.h).
 * --trace: appends "device_time_us,pwm0,..,pwm3" on every change of the four motor
 *   channels named by --motors, device time being the simulated time; each channel's duty
 *   comes from its timer's COM bits and OCR register, or from its pin's PORT bit when the
 *   COM bits disconnect the pin (what Arduino's analogWrite does for 0 and 255).
 * --events: appends, in CPU cycles, "rx_end CYCLE" when the UART receive interrupt starts
 *   for a frame's closing 0x00 (a 0x00 after another byte: the byte a POSE is complete
 *   with), and "pwm CYCLE D0 D1 D2 D3" on every change of the motor channels (the
 *   --trace rows, cycle-exact): device-side POSE -> PWM latencies (graspguide latency).
 * --marks: a write of 1 to GPIOR0 starts a cycle count, 2 appends the cycles since to FILE
 *   (one number a line): a sketch's own probe, e.g. around the handling of one POSE.
 * --stats: written at exit, "key value" lines: cycles, simulated_us, stack_bytes_max (RAMEND
 *   minus the lowest stack pointer seen at any instruction: the sketch's measured stack),
 *   uart_bytes_dropped.
 * --fast: simulated time runs as fast as the host can; by default it is held back to real
 *   time, because the sketch's watchdog counts simulated time and a host streams in real
 *   time.
 * The UART bridge is this program's own, single-threaded, instead of simavr's uart_pty
 * part: that part runs a thread that feeds bytes in real time regardless of simulated
 * time, prints to stdout and re-points one fixed /tmp/simavr-uart0 link, which parallel
 * runs would fight over.
 * Exit: SIGTERM/SIGINT/SIGHUP or the parent's death -> motors off (a last trace row of
 * zeros: the board loses power) and status 0; 1 no pty; 2 bad use or unreadable ELF; 3 the
 * AVR crashed; 4 --max-cycles reached. The AVR sleeping with interrupts off ends the run
 * with status 0.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include <simavr/avr_uart.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_interrupts.h>
#include <simavr/sim_io.h>
#include <simavr/sim_irq.h>

enum { kFrequencyHz = 8000000, kCyclesPerUs = kFrequencyHz / 1000000 };
/* How often (simulated) the pty is serviced and time is synchronised: 100 us is under one
 * byte time at 115200 baud (87 us per bit, 868 us per byte), so no byte waits long. */
enum { kServiceCycles = 800 };
enum { kMarkReg = 0x3E, kStartMark = 1, kStopMark = 2 };
/* ATmega328P data-space addresses. */
enum { kUcsr0b = 0xC1, kRxen0Bit = 4, kSpl = 0x5D, kSph = 0x5E, kRamEnd = 0x8FF };
enum { kMotors = 4 };

typedef struct {
  const char* name;
  uint8_t tccra, ocr_lo, ocr_hi; /* ocr_hi 0: an 8-bit timer */
  uint8_t com_shift;             /* COMxA1:0 at bits 7:6, COMxB1:0 at 5:4 */
  uint8_t port, ddr, bit;        /* the pin the channel drives */
} Channel;

static const Channel kChannels[] = {
    {"OC0A", 0x44, 0x47, 0, 6, 0x2B, 0x2A, 6},    /* PD6, pin 6 */
    {"OC0B", 0x44, 0x48, 0, 4, 0x2B, 0x2A, 5},    /* PD5, pin 5 */
    {"OC1A", 0x80, 0x88, 0x89, 6, 0x25, 0x24, 1}, /* PB1, pin 9 */
    {"OC1B", 0x80, 0x8A, 0x8B, 4, 0x25, 0x24, 2}, /* PB2, pin 10 */
    {"OC2A", 0xB0, 0xB3, 0, 6, 0x25, 0x24, 3},    /* PB3, pin 11 */
    {"OC2B", 0xB0, 0xB4, 0, 4, 0x2B, 0x2A, 3},    /* PD3, pin 3 */
};
enum { kChannelCount = sizeof kChannels / sizeof kChannels[0] };

static volatile sig_atomic_t g_stop;
static const Channel* g_motor[kMotors];
static unsigned g_last_pwm[kMotors];
static int g_pwm_written;
static FILE* g_trace;
static FILE* g_marks;
static FILE* g_events;
/* The bytes fed to the UART, in order, until its receive interrupt takes them (one per
 * interrupt, as the sketch's serial driver reads them): which byte an interrupt is for. */
static uint8_t g_fed[4096];
static size_t g_fed_begin, g_fed_end;
static uint8_t g_last_rx = 0;
enum { kUsartRxVector = 18 }; /* ATmega328P USART_RX */
static avr_cycle_count_t g_mark_start;
static int g_mark_started;
/* UART0 -> host bytes, drained to the pty after every service interval. */
static uint8_t g_out[8192];
static size_t g_out_len;
static unsigned long long g_out_dropped;
static int g_rx_full; /* simavr's UART input FIFO signalled XOFF */
/* Host -> UART bytes read from the pty and not yet taken by simavr's UART. */
static uint8_t g_in[4096];
static size_t g_in_begin, g_in_end;
static unsigned g_min_sp = kRamEnd;

static void on_signal(int sig) {
  (void)sig;
  g_stop = 1;
}

static void log_to_stderr(avr_t* avr, const int level, const char* format, va_list ap) {
  (void)avr;
  if (level <= LOG_WARNING) vfprintf(stderr, format, ap);
}

static void no_sleep(avr_t* avr, avr_cycle_count_t how_long) {
  (void)avr;
  (void)how_long;
}

static unsigned channel_duty(const avr_t* avr, const Channel* c) {
  const unsigned com = (avr->data[c->tccra] >> c->com_shift) & 3u;
  unsigned ocr = avr->data[c->ocr_lo];
  if (c->ocr_hi) ocr |= (unsigned)avr->data[c->ocr_hi] << 8;
  if (com == 2) return ocr;
  if (com == 3) return 255u - (ocr & 255u);
  /* Disconnected from the timer (or toggle mode, which no PWM sketch uses): the pin is
   * a plain output, fully on or off. */
  const int driven = (avr->data[c->ddr] >> c->bit) & 1;
  const int high = (avr->data[c->port] >> c->bit) & 1;
  return driven && high ? 255u : 0u;
}

static void write_trace_row(avr_cycle_count_t cycle, const unsigned* pwm) {
  if (!g_trace) return;
  fprintf(g_trace, "%llu", (unsigned long long)(cycle / kCyclesPerUs));
  for (int i = 0; i < kMotors; ++i) fprintf(g_trace, ",%u", pwm[i]);
  fputc('\n', g_trace);
  fflush(g_trace); /* nothing lost if the runner is killed */
}

static void write_event_pwm(avr_cycle_count_t cycle, const unsigned* pwm) {
  if (!g_events) return;
  fprintf(g_events, "pwm %llu %u %u %u %u\n", (unsigned long long)cycle, pwm[0], pwm[1], pwm[2],
          pwm[3]);
  fflush(g_events);
}

static void sample_motors(const avr_t* avr) {
  unsigned pwm[kMotors];
  int changed = !g_pwm_written;
  for (int i = 0; i < kMotors; ++i) {
    pwm[i] = channel_duty(avr, g_motor[i]);
    if (pwm[i] != g_last_pwm[i]) changed = 1;
  }
  if (!changed) return;
  memcpy(g_last_pwm, pwm, sizeof pwm);
  g_pwm_written = 1;
  write_trace_row(avr->cycle, pwm);
  write_event_pwm(avr->cycle, pwm);
}

static void motors_off(const avr_t* avr) {
  static const unsigned off[kMotors];
  if (g_pwm_written && memcmp(g_last_pwm, off, sizeof off) == 0) return;
  memcpy(g_last_pwm, off, sizeof off);
  g_pwm_written = 1;
  write_trace_row(avr->cycle, off);
}

static void on_uart_out(struct avr_irq_t* irq, uint32_t value, void* param) {
  (void)irq;
  (void)param;
  if (g_out_len < sizeof g_out) {
    g_out[g_out_len++] = (uint8_t)value;
  } else {
    ++g_out_dropped; /* the host stopped reading for 8 KB: as a real link would lose it */
  }
}

static void on_uart_xon(struct avr_irq_t* irq, uint32_t value, void* param) {
  (void)irq;
  (void)value;
  (void)param;
  g_rx_full = 0;
}

static void on_uart_xoff(struct avr_irq_t* irq, uint32_t value, void* param) {
  (void)irq;
  (void)param;
  g_rx_full = value != 0; /* simavr raises XOFF 0 when its FIFO empties */
}

static void on_rx_interrupt(struct avr_irq_t* irq, uint32_t value, void* param) {
  (void)irq;
  const avr_t* avr = param;
  if (!value || g_fed_begin == g_fed_end) return; /* the ISR's end, or not a fed byte */
  const uint8_t byte = g_fed[g_fed_begin++ % sizeof g_fed];
  if (byte == 0 && g_last_rx != 0 && g_events) {
    fprintf(g_events, "rx_end %llu\n", (unsigned long long)avr->cycle);
    fflush(g_events);
  }
  g_last_rx = byte;
}

static void on_mark(avr_t* avr, avr_io_addr_t addr, uint8_t v, void* param) {
  (void)addr;
  (void)param;
  if (v == kStartMark) {
    g_mark_start = avr->cycle;
    g_mark_started = 1;
  } else if (v == kStopMark && g_mark_started && g_marks) {
    fprintf(g_marks, "%llu\n", (unsigned long long)(avr->cycle - g_mark_start));
    fflush(g_marks);
    g_mark_started = 0;
  }
}

/* Host -> UART: held until the sketch enables its receiver (a real board's bootloader
 * would swallow them anyway), then fed whenever simavr's UART FIFO has room (it signals
 * XON), so a burst is limited by the programmed baud rate, not by this loop; the UART
 * model delivers them to the AVR at that rate. */
static void feed_uart(const avr_t* avr, avr_irq_t* uart_in) {
  if (!((avr->data[kUcsr0b] >> kRxen0Bit) & 1)) return;
  while (g_in_begin < g_in_end && !g_rx_full) {
    if (g_events && g_fed_end - g_fed_begin < sizeof g_fed)
      g_fed[g_fed_end++ % sizeof g_fed] = g_in[g_in_begin];
    avr_raise_irq(uart_in, g_in[g_in_begin++]);
  }
}

static int open_pty(int* slave_keepalive, char* path, size_t path_size) {
  const int master = posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK);
  if (master < 0 || grantpt(master) != 0 || unlockpt(master) != 0) return -1;
  const char* name = ptsname(master);
  if (!name || strlen(name) + 1 > path_size) return -1;
  strcpy(path, name);
  /* Held open so the pty survives the host closing and reopening it, and set raw so
   * binary frames pass unchanged. */
  *slave_keepalive = open(name, O_RDWR | O_NOCTTY | O_NONBLOCK);
  if (*slave_keepalive < 0) return -1;
  struct termios tio;
  if (tcgetattr(*slave_keepalive, &tio) != 0) return -1;
  cfmakeraw(&tio);
  if (tcsetattr(*slave_keepalive, TCSANOW, &tio) != 0) return -1;
  return master;
}

static int parse_motors(const char* list) {
  char buf[64];
  if (strlen(list) >= sizeof buf) return 0;
  strcpy(buf, list);
  int n = 0;
  for (char* tok = strtok(buf, ","); tok; tok = strtok(NULL, ",")) {
    if (n == kMotors) return 0;
    const Channel* found = NULL;
    for (int i = 0; i < kChannelCount; ++i)
      if (strcmp(tok, kChannels[i].name) == 0) found = &kChannels[i];
    if (!found) return 0;
    g_motor[n++] = found;
  }
  return n == kMotors;
}

static double now_us(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec * 1e6 + ts.tv_nsec / 1e3;
}

static void usage(const char* argv0) {
  fprintf(stderr,
          "usage: %s FIRMWARE.elf [--trace FILE.csv] [--motors OC2B,OC1A,OC1B,OC2A] "
          "[--events FILE] [--marks FILE] [--stats FILE] [--fast] [--max-cycles N]\n"
          "  --motors: the four timer channels that drive motors 0..3, each one of "
          "OC0A OC0B OC1A OC1B OC2A OC2B\n",
          argv0);
}

int main(int argc, char** argv) {
  const pid_t parent = getppid(); /* if the parent dies, getppid() changes */
  const char* elf_path = NULL;
  const char* trace_path = NULL;
  const char* marks_path = NULL;
  const char* events_path = NULL;
  const char* stats_path = NULL;
  const char* motors = "OC2B,OC1A,OC1B,OC2A";
  int fast = 0;
  unsigned long long max_cycles = 0;
  for (int i = 1; i < argc; ++i) {
    if (strcmp(argv[i], "--trace") == 0 && i + 1 < argc) {
      trace_path = argv[++i];
    } else if (strcmp(argv[i], "--events") == 0 && i + 1 < argc) {
      events_path = argv[++i];
    } else if (strcmp(argv[i], "--marks") == 0 && i + 1 < argc) {
      marks_path = argv[++i];
    } else if (strcmp(argv[i], "--stats") == 0 && i + 1 < argc) {
      stats_path = argv[++i];
    } else if (strcmp(argv[i], "--motors") == 0 && i + 1 < argc) {
      motors = argv[++i];
    } else if (strcmp(argv[i], "--fast") == 0) {
      fast = 1;
    } else if (strcmp(argv[i], "--max-cycles") == 0 && i + 1 < argc) {
      max_cycles = strtoull(argv[++i], NULL, 10);
    } else if (argv[i][0] != '-' && !elf_path) {
      elf_path = argv[i];
    } else {
      usage(argv[0]);
      return 2;
    }
  }
  if (!elf_path) {
    usage(argv[0]);
    return 2;
  }
  if (!parse_motors(motors)) {
    fprintf(stderr, "promini_sim_runner: --motors '%s' must name four channels\n", motors);
    usage(argv[0]);
    return 2;
  }
  if (trace_path && !(g_trace = fopen(trace_path, "a"))) {
    fprintf(stderr, "promini_sim_runner: cannot open trace file '%s'\n", trace_path);
    return 2;
  }
  if (marks_path && !(g_marks = fopen(marks_path, "a"))) {
    fprintf(stderr, "promini_sim_runner: cannot open marks file '%s'\n", marks_path);
    return 2;
  }
  if (events_path && !(g_events = fopen(events_path, "a"))) {
    fprintf(stderr, "promini_sim_runner: cannot open events file '%s'\n", events_path);
    return 2;
  }
  if (g_trace) fprintf(g_trace, "device_time_us,pwm0,pwm1,pwm2,pwm3\n");

  avr_global_logger_set(log_to_stderr);
  static elf_firmware_t fw;
  if (elf_read_firmware(elf_path, &fw) != 0) {
    fprintf(stderr, "promini_sim_runner: cannot read %s\n", elf_path);
    return 2;
  }
  avr_t* avr = avr_make_mcu_by_name("atmega328p");
  if (!avr) {
    fprintf(stderr, "promini_sim_runner: this simavr has no atmega328p\n");
    return 2;
  }
  avr_init(avr);
  avr_load_firmware(avr, &fw);
  avr->frequency = kFrequencyHz;
  /* Real time is kept by this loop, not by simavr's sleep (which would usleep while
   * the pty goes unserviced). */
  avr->sleep = no_sleep;
  avr_register_io_write(avr, kMarkReg, on_mark, NULL);
  if (g_events) {
    avr_irq_t* rx_vector = avr_get_interrupt_irq(avr, kUsartRxVector);
    if (!rx_vector) {
      fprintf(stderr, "promini_sim_runner: no USART_RX interrupt vector to watch\n");
      return 2;
    }
    avr_irq_register_notify(rx_vector + AVR_INT_IRQ_RUNNING, on_rx_interrupt, avr);
  }
  avr_irq_t* uart_in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
                          on_uart_out, NULL);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON),
                          on_uart_xon, NULL);
  avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF),
                          on_uart_xoff, NULL);
  /* simavr's UART polls with a real-time sleep when the AVR busy-waits on RXC; off. */
  uint32_t uart_flags = 0;
  avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &uart_flags);
  uart_flags &= ~(uint32_t)(AVR_UART_FLAG_POLL_SLEEP | AVR_UART_FLAG_STDIO);
  avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &uart_flags);

  int slave_keepalive = -1;
  char pty_path[256];
  const int master = open_pty(&slave_keepalive, pty_path, sizeof pty_path);
  if (master < 0) {
    perror("promini_sim_runner: cannot open a pseudo-terminal");
    return 1;
  }
  signal(SIGINT, on_signal);
  signal(SIGTERM, on_signal);
  signal(SIGHUP, on_signal);
  signal(SIGPIPE, SIG_IGN);
  printf("GRASPGUIDE_SIM_PTY %s\n", pty_path);
  fflush(stdout);

  const double t0_us = now_us();
  int state = cpu_Running;
  int status = 0;
  sample_motors(avr);
  while (!g_stop && getppid() == parent) {
    const avr_cycle_count_t until = avr->cycle + kServiceCycles;
    while (avr->cycle < until && state != cpu_Done && state != cpu_Crashed) {
      state = avr_run(avr);
      sample_motors(avr);
      if (g_in_begin < g_in_end && !g_rx_full) feed_uart(avr, uart_in);
      const unsigned sp = avr->data[kSpl] | (unsigned)avr->data[kSph] << 8;
      if (sp < g_min_sp) g_min_sp = sp;
    }
    if (state == cpu_Crashed) {
      fprintf(stderr, "promini_sim_runner: the AVR crashed at cycle %llu (pc 0x%x)\n",
              (unsigned long long)avr->cycle, (unsigned)avr->pc);
      status = 3;
      break;
    }
    if (max_cycles && avr->cycle >= max_cycles) {
      fprintf(stderr, "promini_sim_runner: --max-cycles %llu reached\n", max_cycles);
      status = 4;
      break;
    }
    if (g_in_begin == g_in_end) {
      const ssize_t n = read(master, g_in, sizeof g_in);
      if (n > 0) {
        g_in_begin = 0;
        g_in_end = (size_t)n;
      }
    }
    feed_uart(avr, uart_in);
    if (g_out_len > 0) {
      const ssize_t n = write(master, g_out, g_out_len);
      if (n > 0) {
        memmove(g_out, g_out + n, g_out_len - (size_t)n);
        g_out_len -= (size_t)n;
      }
    }
    if (state == cpu_Done) break; /* slept with interrupts off: the sketch ended */
    if (!fast) {
      const double ahead_us = (double)avr->cycle / kCyclesPerUs - (now_us() - t0_us);
      if (ahead_us > 200.0) {
        /* Waits for host bytes too, so a pose is not held back by the sleep. */
        struct pollfd p = {master, POLLIN, 0};
        const long long ahead_ns = (long long)(ahead_us * 1000.0);
        const struct timespec ts = {(time_t)(ahead_ns / 1000000000), (long)(ahead_ns % 1000000000)};
        if (g_in_begin == g_in_end) {
          ppoll(&p, 1, &ts, NULL);
        } else {
          nanosleep(&ts, NULL); /* bytes wait for the UART anyway */
        }
      }
    }
  }
  motors_off(avr); /* power off: every pin low, whatever the sketch last did */
  if (g_out_len > 0 && write(master, g_out, g_out_len) < 0) g_out_dropped += g_out_len;
  /* Closing the master discards what the host has not read yet (the sketch's last answer):
   * give it up to kDrainMs to read it. The kernel moves bytes from the master to the
   * slave's queue asynchronously, so an empty queue counts only after kSettleMs. */
  enum { kDrainMs = 500, kSettleMs = 20 };
  for (int waited_ms = 0; waited_ms < kDrainMs && getppid() == parent; ++waited_ms) {
    int queued = 0;
    if (ioctl(slave_keepalive, FIONREAD, &queued) != 0) break;
    if (queued == 0 && waited_ms >= kSettleMs) break;
    const struct timespec ms = {0, 1000000};
    nanosleep(&ms, NULL);
  }
  if (g_out_dropped)
    fprintf(stderr, "promini_sim_runner: %llu UART bytes dropped (the host did not read)\n",
            g_out_dropped);
  fprintf(stderr, "promini_sim_runner: %llu cycles (%.3f s simulated)\n",
          (unsigned long long)avr->cycle, (double)avr->cycle / kFrequencyHz);
  FILE* stats = stats_path ? fopen(stats_path, "w") : NULL;
  if (stats) {
    fprintf(stats, "cycles %llu\nsimulated_us %llu\nstack_bytes_max %u\nuart_bytes_dropped %llu\n",
            (unsigned long long)avr->cycle, (unsigned long long)(avr->cycle / kCyclesPerUs),
            kRamEnd - g_min_sp, g_out_dropped);
    fclose(stats);
  } else if (stats_path) {
    fprintf(stderr, "promini_sim_runner: cannot write stats file '%s'\n", stats_path);
  }
  if (g_trace) fclose(g_trace);
  if (g_marks) fclose(g_marks);
  if (g_events) fclose(g_events);
  close(slave_keepalive);
  close(master);
  return status;
}
