// Board wiring and link settings of the wearable controller. Every value is a default:
// override any of them from platformio.ini `build_flags`, e.g. -DGRASPGUIDE_MOTOR_PINS=25,26,27,33.
// Motor order is the protocol's contact order: 0 thumb, 1 index, 2 middle, 3 palm.
#pragma once

#if defined(ARDUINO_FEATHER_ESP32) || defined(GRASPGUIDE_BOARD_FEATHERESP32)
// Adafruit HUZZAH32 Feather: four LEDC-capable pins that are neither strapping pins nor
// input-only (34..39), adjacent on the header.
#define GRASPGUIDE_BOARD_DEFAULT_NAME "featheresp32"
#define GRASPGUIDE_BOARD_DEFAULT_PINS 13, 12, 27, 33
// GPIO32: next to 33 on the header, not a strapping pin, has an internal pull-up.
#define GRASPGUIDE_BOARD_DEFAULT_BUTTON_PIN 32
#elif defined(ARDUINO_TEENSY40) || defined(GRASPGUIDE_BOARD_TEENSY40)
// Teensy 4.0: pins 2..5 are FlexPWM outputs.
#define GRASPGUIDE_BOARD_DEFAULT_NAME "teensy40"
#define GRASPGUIDE_BOARD_DEFAULT_PINS 2, 3, 4, 5
#define GRASPGUIDE_BOARD_DEFAULT_BUTTON_PIN 6
#else
#define GRASPGUIDE_BOARD_DEFAULT_NAME "arduino"
#define GRASPGUIDE_BOARD_DEFAULT_PINS 3, 5, 6, 9
#define GRASPGUIDE_BOARD_DEFAULT_BUTTON_PIN 2
#endif

// Reported in HELLO_REPLY (at most 15 characters).
#ifndef GRASPGUIDE_BOARD_NAME
#define GRASPGUIDE_BOARD_NAME GRASPGUIDE_BOARD_DEFAULT_NAME
#endif

// One output pin per motor, thumb, index, middle, palm.
#ifndef GRASPGUIDE_MOTOR_PINS
#define GRASPGUIDE_MOTOR_PINS GRASPGUIDE_BOARD_DEFAULT_PINS
#endif

// The IMU on the back of the hand, on the board's default I2C bus (Wire) at the part's
// default address. LSM6DSOX: a 6-axis part (accelerometer + gyroscope; the device estimates
// gravity). BNO055: on-chip fusion, the chip's gravity vector. NONE: no IMU (tracker only).
#define GRASPGUIDE_IMU_NONE 0
#define GRASPGUIDE_IMU_LSM6DSOX 1
#define GRASPGUIDE_IMU_BNO055 2
#ifndef GRASPGUIDE_IMU
#define GRASPGUIDE_IMU GRASPGUIDE_IMU_LSM6DSOX
#endif

// One IMU read per 10 ms (100 Hz): the rate the health thresholds are argued for
// (graspguide_cue/imu_watchdog.h). Slower than the LSM6DSOX's 104 Hz output, so every read
// is a fresh conversion; the BNO055 fuses at 100 Hz.
#ifndef GRASPGUIDE_IMU_PERIOD_US
#define GRASPGUIDE_IMU_PERIOD_US 10000
#endif

// The host-less mode (a stored plan run with the IMU and the button, no PC) needs
// an IMU and a store that holds the plan region (8 KiB) and its log: the ESP32's LittleFS
// partition. The Teensy 4.0's EEPROM emulation is 1,080 bytes and a generic core has no file
// API common to all boards, so those builds have no host-less mode. 1 on a board without
// LittleFS is an error, not a silent fallback.
#ifndef GRASPGUIDE_HOSTLESS
#if defined(ARDUINO_ARCH_ESP32) && GRASPGUIDE_IMU != GRASPGUIDE_IMU_NONE
#define GRASPGUIDE_HOSTLESS 1
#else
#define GRASPGUIDE_HOSTLESS 0
#endif
#endif

// The host-less store: a file on the LittleFS partition (labelled "spiffs"; the core's
// default.csv partition table gives it 1.375 MiB of a 4 MB flash). 64 KiB holds the plan region and
// 796 trial records, six 128-trial plans' worth, like the simulated device's default store.
#ifndef GRASPGUIDE_STORE_PATH
#define GRASPGUIDE_STORE_PATH "/graspguide.bin"
#endif
#ifndef GRASPGUIDE_STORE_BYTES
#define GRASPGUIDE_STORE_BYTES 65536
#endif

// The button that starts a host-less trial, between this pin and GND (internal pull-up).
#ifndef GRASPGUIDE_BUTTON_PIN
#define GRASPGUIDE_BUTTON_PIN GRASPGUIDE_BOARD_DEFAULT_BUTTON_PIN
#endif

// A level must hold this long to count: tactile switches bounce for under 10 ms, and a
// deliberate press lasts 100 ms or more.
#ifndef GRASPGUIDE_BUTTON_DEBOUNCE_MS
#define GRASPGUIDE_BUTTON_DEBOUNCE_MS 20
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
