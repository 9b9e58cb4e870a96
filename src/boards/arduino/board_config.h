// Board wiring and link settings of the wearable controller. Every value is a default:
// override any of them from platformio.ini `build_flags`, e.g. -DGRASPGUIDE_MOTOR_PINS=25,26,27,33.
// Motor order is the protocol's contact order: 0 thumb, 1 index, 2 middle, 3 palm.
#pragma once

#if defined(ARDUINO_FEATHER_ESP32) || defined(GRASPGUIDE_BOARD_FEATHERESP32)
// Adafruit HUZZAH32 Feather: four LEDC-capable pins that are neither strapping pins nor
// input-only (34..39), adjacent on the header.
#define GRASPGUIDE_BOARD_DEFAULT_NAME "featheresp32"
#define GRASPGUIDE_BOARD_DEFAULT_PINS 13, 12, 27, 33
#elif defined(ARDUINO_TEENSY40) || defined(GRASPGUIDE_BOARD_TEENSY40)
// Teensy 4.0: pins 2..5 are FlexPWM outputs.
#define GRASPGUIDE_BOARD_DEFAULT_NAME "teensy40"
#define GRASPGUIDE_BOARD_DEFAULT_PINS 2, 3, 4, 5
#else
#define GRASPGUIDE_BOARD_DEFAULT_NAME "arduino"
#define GRASPGUIDE_BOARD_DEFAULT_PINS 3, 5, 6, 9
#endif

// Reported in HELLO_REPLY (at most 15 characters).
#ifndef GRASPGUIDE_BOARD_NAME
#define GRASPGUIDE_BOARD_NAME GRASPGUIDE_BOARD_DEFAULT_NAME
#endif

// One output pin per motor, thumb, index, middle, palm.
#ifndef GRASPGUIDE_MOTOR_PINS
#define GRASPGUIDE_MOTOR_PINS GRASPGUIDE_BOARD_DEFAULT_PINS
#endif

// Above hearing and well above an ERM's mechanical bandwidth, so the motor only sees
// the mean voltage; the paper's Arduino ran at ~490 Hz, which buzzes audibly.
#ifndef GRASPGUIDE_PWM_FREQUENCY_HZ
#define GRASPGUIDE_PWM_FREQUENCY_HZ 20000
#endif

// The protocol carries 8-bit duty values; the timer resolution matches them.
#define GRASPGUIDE_PWM_RESOLUTION_BITS 8

// USB serial baud rate (ignored by native-USB boards such as the Teensy).
#ifndef GRASPGUIDE_SERIAL_BAUD
#define GRASPGUIDE_SERIAL_BAUD 115200
#endif

// Bluetooth (classic SPP) device name, ESP32 only.
#ifndef GRASPGUIDE_BT_NAME
#define GRASPGUIDE_BT_NAME "GraspGuide"
#endif

// 1 to open the Bluetooth serial link next to USB (ESP32 only).
#ifndef GRASPGUIDE_USE_BLUETOOTH
#if defined(ARDUINO_ARCH_ESP32)
#define GRASPGUIDE_USE_BLUETOOTH 1
#else
#define GRASPGUIDE_USE_BLUETOOTH 0
#endif
#endif

// Stamped into HELLO_REPLY so a log names the firmware it came from (set by the build).
#ifndef GRASPGUIDE_BUILD_ID
#define GRASPGUIDE_BUILD_ID 0
#endif
