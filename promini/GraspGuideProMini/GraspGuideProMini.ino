// GraspGuide on the paper's board: Arduino Pro Mini 3.3 V / 8 MHz (ATmega328P) + RN-42.
//
// This file holds only this comment. The code is in the .cpp files of this folder:
// Debian's universal-ctags does not generate the prototypes Arduino's own ctags fork
// does, so functions in a .ino would not compile with the offline toolchain
// (tools/bootstrap.sh, `python -m graspguide.promini.build`).
//
//   board_glue.h/.cpp     Serial (UART0, 115200 baud), PWM on D3, D9, D10, D11, micros()
//   GraspGuideProMini.cpp setup() and loop(): motors off, then poll the device
//
// The device itself (the protocol subset, SET_POSTURE, POSE -> PWM, the trial, the
// watchdog) is the Arduino library lib/graspguide_cue_device on lib/graspguide_cue, with
// the board's interfaces from lib/graspguide_hal.
