// The trap handler of the images run under QEMU: it replaces syscalls.cpp's weak m4f_halt,
// so a trap ends the run with a code and a HALT line instead of hanging the emulator.
// Include it from exactly one file of an image.
#pragma once

#include <cstdint>

#include "line_buffer.h"
#include "semihosting.h"

extern "C" {
uint32_t m4f_stack_high_water(void);  // startup.c
[[noreturn]] void m4f_halt(int reason, int code) {
  stages::LineBuffer line;
  stages::write0(line.str("HALT ").num(reason).sp().num(code).end());
  stages::exit(100 + reason);
}
}
