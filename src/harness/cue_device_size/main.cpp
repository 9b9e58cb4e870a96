// The per-frame-only device on the ATmega328P's own peripherals, for its flash and static
// RAM (`pio run -e cue_device_avr`, then avr-size): UART0 at 115200 baud polled, Timer0
// and Timer2's four PWM outputs as the motors, Timer1 counting microseconds. Minimal on
// purpose: the Arduino sketch (promini/) is the board's real entry point; this image only
// keeps what the device links, so its size is the device's.
#include <avr/io.h>

#include "graspguide_cue_device.h"

namespace gfd = graspguide::cue_device;

namespace {

class Uart0 final : public graspguide::hal::ByteStream {
 public:
  Uart0() {
    // 8 MHz, U2X: UBRR 8 gives 111,111 baud (-3.5 %), what the Pro Mini's core uses.
    UCSR0A = _BV(U2X0);
    UBRR0 = 8;
    UCSR0B = _BV(RXEN0) | _BV(TXEN0);
  }
  size_t read(uint8_t* buffer, size_t capacity) override {
    size_t n = 0;
    while (n < capacity && (UCSR0A & _BV(RXC0))) buffer[n++] = UDR0;
    return n;
  }
  size_t write(const uint8_t* data, size_t length) override {
    for (size_t i = 0; i < length; ++i) {
      while (!(UCSR0A & _BV(UDRE0))) {
      }
      UDR0 = data[i];
    }
    return length;
  }
};

// OC0A (D6), OC0B (D5), OC2A (D11), OC2B (D3): fast PWM.
class TimerMotors final : public graspguide::hal::MotorOutputs {
 public:
  TimerMotors() {
    DDRD |= _BV(PD6) | _BV(PD5) | _BV(PD3);
    DDRB |= _BV(PB3);
    TCCR0A = _BV(COM0A1) | _BV(COM0B1) | _BV(WGM01) | _BV(WGM00);
    TCCR0B = _BV(CS01);
    TCCR2A = _BV(COM2A1) | _BV(COM2B1) | _BV(WGM21) | _BV(WGM20);
    TCCR2B = _BV(CS21);
  }
  void write(const graspguide::Pwm& pwm) override {
    OCR0A = pwm.duty[0];
    OCR0B = pwm.duty[1];
    OCR2A = pwm.duty[2];
    OCR2B = pwm.duty[3];
  }
};

// Timer1 at F_CPU / 8 = 1 MHz: one count per microsecond, widened to 32 bits by polling
// (the device polls far more often than every 65 ms).
class Timer1Clock final : public graspguide::hal::Clock {
 public:
  Timer1Clock() { TCCR1B = _BV(CS11); }
  uint32_t now_us() override {
    const uint16_t t = TCNT1;
    high_ += uint16_t(t < last_) ? 0x10000ul : 0;
    last_ = t;
    return high_ | t;
  }

 private:
  uint32_t high_ = 0;
  uint16_t last_ = 0;
};

}  // namespace

int main() {
  static Uart0 uart;
  static TimerMotors motors;
  static Timer1Clock clock;
  static gfd::CueDevice device(uart, motors, clock, gfd::DeviceInfo{});
  for (;;) device.poll();
}
