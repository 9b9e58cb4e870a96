// The three hardware interfaces on the standard Arduino API, for any board whose core
// provides micros(), Stream and analogWrite; ESP32's LEDC lives in esp32_ledc_motors.h.
#pragma once

#include <Arduino.h>

#include "graspguide_hal/hal.h"

namespace graspguide::board {

class MicrosClock final : public graspguide::hal::Clock {
 public:
  uint32_t now_us() override { return micros(); }
};

// A serial port (USB CDC, UART or Bluetooth SPP). When check_space is set, a frame that
// does not fit in the transmit buffer is dropped whole (the host counts it as a missing
// TELEMETRY) instead of blocking the control loop; ports whose availableForWrite() is
// not implemented (ESP32 BluetoothSerial returns 0) must pass false.
class SerialByteStream final : public graspguide::hal::ByteStream {
 public:
  SerialByteStream(Stream& port, bool check_space) : port_(port), check_space_(check_space) {}

  size_t read(uint8_t* buffer, size_t capacity) override {
    size_t n = 0;
    while (n < capacity && port_.available() > 0) {
      const int c = port_.read();
      if (c < 0) break;
      buffer[n++] = uint8_t(c);
    }
    return n;
  }

  size_t write(const uint8_t* data, size_t length) override {
    if (check_space_ && size_t(port_.availableForWrite()) < length) return 0;
    return port_.write(data, length);
  }

 private:
  Stream& port_;
  bool check_space_;
};

// Copies the motor pins and drives them low as outputs: called from constructors, so the
// motors are off before setup() runs.
template <int K>
void drive_low(const uint8_t (&pins)[K], uint8_t (&kept)[K]) {
  for (int i = 0; i < K; ++i) {
    kept[i] = pins[i];
    digitalWrite(kept[i], LOW);
    pinMode(kept[i], OUTPUT);
  }
}

// analogWrite() outputs (Teensy, AVR, SAMD, RP2040...). Pins are driven low before
// anything else runs, so the motors are off from the first microsecond of setup().
template <int K>
class AnalogWriteMotors final : public graspguide::hal::MotorOutputs {
 public:
  explicit AnalogWriteMotors(const uint8_t (&pins)[K]) { drive_low(pins, pins_); }

  void begin(uint32_t frequency_hz) {
#if defined(TEENSYDUINO)
    analogWriteResolution(8);
    for (int i = 0; i < K; ++i) analogWriteFrequency(pins_[i], float(frequency_hz));
#else
    (void)frequency_hz;  // AVR's analogWrite frequency is fixed by its core
#endif
    write(Pwm{});
  }

  void write(const Pwm& pwm) override {
    for (int i = 0; i < K; ++i) analogWrite(pins_[i], pwm.duty[i]);
  }

 private:
  uint8_t pins_[K] = {};
};

}  // namespace graspguide::board
