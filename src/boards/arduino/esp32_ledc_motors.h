// ESP32 motor outputs on the LEDC peripheral (analogWrite there is LEDC with a fixed
// 1 kHz, which buzzes). Channel i drives motor i.
#pragma once

#if defined(ARDUINO_ARCH_ESP32)

#include <Arduino.h>

#include "arduino_hal.h"

namespace graspguide::board {

template <int K>
class Esp32LedcMotors final : public graspguide::hal::MotorOutputs {
 public:
  explicit Esp32LedcMotors(const uint8_t (&pins)[K]) { drive_low(pins, pins_); }

  void begin(uint32_t frequency_hz, uint8_t resolution_bits) {
    for (int i = 0; i < K; ++i) {
#if ESP_ARDUINO_VERSION_MAJOR >= 3
      ledcAttach(pins_[i], frequency_hz, resolution_bits);
#else
      ledcSetup(uint8_t(i), double(frequency_hz), resolution_bits);
      ledcAttachPin(pins_[i], uint8_t(i));
#endif
    }
    write(Pwm{});
  }

  void write(const Pwm& pwm) override {
    for (int i = 0; i < K; ++i) {
#if ESP_ARDUINO_VERSION_MAJOR >= 3
      ledcWrite(pins_[i], pwm.duty[i]);
#else
      ledcWrite(uint8_t(i), pwm.duty[i]);
#endif
    }
  }

 private:
  uint8_t pins_[K] = {};
};

}  // namespace graspguide::board

#endif  // ARDUINO_ARCH_ESP32
