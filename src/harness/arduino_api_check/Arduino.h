// A minimal stand-in for the Arduino API, only what src/boards/arduino/ calls, so that the
// board code compiles and links on the host (`pio run -e arduino_check_*`). It proves the
// code compiles against these signatures, not that it runs on a board: every function
// here does nothing. The real cores (ESP32, Teensy, AVR) are not reachable from this
// project's build machines. The board is chosen by the macros its real core defines
// (ARDUINO_ARCH_ESP32, TEENSYDUINO), set in platformio.ini.
#pragma once

#include <cstddef>
#include <cstdint>

constexpr uint8_t LOW = 0;
constexpr uint8_t HIGH = 1;
constexpr uint8_t OUTPUT = 1;
constexpr uint8_t INPUT_PULLUP = 2;

typedef bool boolean;

void pinMode(uint8_t pin, uint8_t mode);
void digitalWrite(uint8_t pin, uint8_t value);
int digitalRead(uint8_t pin);
void analogWrite(uint8_t pin, int value);
unsigned long millis();
unsigned long micros();
void delay(unsigned long ms);

class Stream {
 public:
  virtual int available() { return 0; }
  virtual int read() { return -1; }
  virtual int availableForWrite() { return 0; }
  virtual size_t write(const uint8_t* /*buffer*/, size_t size) { return size; }

 protected:
  ~Stream() = default;
};

class HardwareSerial final : public Stream {
 public:
  void begin(unsigned long /*baud*/) {}
};

extern HardwareSerial Serial;

#if defined(TEENSYDUINO)
void analogWriteResolution(uint32_t bits);
void analogWriteFrequency(uint8_t pin, float frequency_hz);
#endif

#if defined(ARDUINO_ARCH_ESP32)
// The core version comes from esp_arduino_version.h on a real ESP32; PlatformIO's
// espressif32 platform ships core 2.x.
#ifndef ESP_ARDUINO_VERSION_MAJOR
#define ESP_ARDUINO_VERSION_MAJOR 2
#endif
// The loop task's stack size, as esp32-hal.h declares it (cores 2.x and 3.x).
#define SET_LOOP_TASK_STACK_SIZE(sz) \
  size_t getArduinoLoopTaskStackSize() { return sz; }
#if ESP_ARDUINO_VERSION_MAJOR >= 3
bool ledcAttach(uint8_t pin, uint32_t frequency_hz, uint8_t resolution_bits);
bool ledcWrite(uint8_t pin, uint32_t duty);
#else
uint32_t ledcSetup(uint8_t channel, uint32_t frequency_hz, uint8_t resolution_bits);
void ledcAttachPin(uint8_t pin, uint8_t channel);
void ledcWrite(uint8_t channel, uint32_t duty);
#endif
#endif
