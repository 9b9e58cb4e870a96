#include "board_glue.h"

#include <Arduino.h>

namespace graspguide {
namespace promini {

size_t SerialStream::read(uint8_t* buffer, size_t capacity) {
  size_t n = 0;
  while (n < capacity && Serial.available() > 0) {
    buffer[n++] = static_cast<uint8_t>(Serial.read());
  }
  return n;
}

size_t SerialStream::write(const uint8_t* data, size_t length) {
  return Serial.write(data, length);
}

void PwmMotors::begin() {
  for (uint8_t pin : kMotorPins) {
    // Level first, then direction: the pin never drives high, even for one instruction.
    digitalWrite(pin, LOW);
    pinMode(pin, OUTPUT);
  }
}

void PwmMotors::write(const graspguide::Pwm& pwm) {
  for (uint8_t i = 0; i < graspguide::kMaxContacts; ++i) {
    analogWrite(kMotorPins[i], pwm.duty[i]);
  }
}

uint32_t MicrosClock::now_us() { return micros(); }

}  // namespace promini
}  // namespace graspguide
