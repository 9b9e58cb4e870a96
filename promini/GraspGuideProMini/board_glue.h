// The Pro Mini's side of the device's three small interfaces: UART0, four PWM pins, micros().
#pragma once

#include <stddef.h>
#include <stdint.h>

// Each library before the one that needs it: arduino-cli finds a library by the header
// an include names, so graspguide_hal.h comes before graspguide_cue_device.h uses it.
#include <graspguide_cue.h>
#include <graspguide_hal.h>

#include <graspguide_cue_device.h>

namespace graspguide {
namespace promini {

// 115200 baud: the RN-42's factory UART rate (it is transparent, so a USB-serial adapter on
// the same pins behaves the same). At 8 MHz the core's U2X divider gives 111,111 baud
// (-3.5 %): what the paper's board ran, though marginal for a strict receiver.
constexpr uint32_t kBaud = 115200;

// Timer2 (OC2B = D3, OC2A = D11) and Timer1 (OC1A = D9, OC1B = D10): the core runs all four
// in 8-bit phase-correct PWM at one frequency (F_CPU / 64 / 510 = 245 Hz), and none is on
// Timer0, whose overflow interrupt is micros(). Motor i is on kMotorPins[i]. A duty of 0 or
// 255 is a plain low or high pin (analogWrite disconnects the timer there).
constexpr uint8_t kMotorPins[graspguide::kMaxContacts] = {3, 9, 10, 11};

class SerialStream final : public graspguide::hal::ByteStream {
 public:
  size_t read(uint8_t* buffer, size_t capacity) override;
  size_t write(const uint8_t* data, size_t length) override;
};

class PwmMotors final : public graspguide::hal::MotorOutputs {
 public:
  // Drives every motor pin low and makes it an output.
  void begin();
  void write(const graspguide::Pwm& pwm) override;
};

class MicrosClock final : public graspguide::hal::Clock {
 public:
  uint32_t now_us() override;
};

}  // namespace promini
}  // namespace graspguide
