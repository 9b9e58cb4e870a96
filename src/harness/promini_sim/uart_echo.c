/* A tiny ATmega328P program that tests promini_sim_runner without the real sketch: it
 * echoes every UART0 byte (115200 baud at 8 MHz, the Arduino core's U2X setting) and shows
 * it as PWM, the way Arduino's analogWrite drives a pin:
 *   byte b -> OC0A (pin 6) duty b, OC2B (pin 3) duty 255 - b; 0 and 255 disconnect the
 *   timer and drive the pin low or high;
 *   'Q' (0x51) -> cli + sleep: the runner ends with status 0;
 *   each byte's handling is bracketed by GPIOR0 marks 1 and 2 (the runner's --marks).
 *   avr-gcc -mmcu=atmega328p -DF_CPU=8000000UL -Os uart_echo.c -o uart_echo.elf
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <stdint.h>

static void pwm_pin(volatile uint8_t* tccra, uint8_t com1_bit, volatile uint8_t* ocr,
                    volatile uint8_t* port, uint8_t pin, uint8_t duty) {
  if (duty == 0 || duty == 255) {
    *tccra &= (uint8_t)~_BV(com1_bit);
    if (duty) {
      *port |= _BV(pin);
    } else {
      *port &= (uint8_t)~_BV(pin);
    }
  } else {
    *ocr = duty;
    *tccra |= _BV(com1_bit);
  }
}

int main(void) {
  /* Motors off at boot: pins low outputs, timers in fast PWM, disconnected. */
  PORTD &= (uint8_t)~(_BV(PD6) | _BV(PD3));
  DDRD |= _BV(PD6) | _BV(PD3);
  TCCR0A = _BV(WGM01) | _BV(WGM00);
  TCCR0B = _BV(CS01) | _BV(CS00);
  TCCR2A = _BV(WGM21) | _BV(WGM20);
  TCCR2B = _BV(CS22);
  UCSR0A = _BV(U2X0);
  UBRR0 = 8;
  UCSR0C = _BV(UCSZ01) | _BV(UCSZ00);
  UCSR0B = _BV(RXEN0) | _BV(TXEN0);
  for (;;) {
    while (!(UCSR0A & _BV(RXC0))) {
    }
    const uint8_t b = UDR0;
    GPIOR0 = 1;
    if (b == 'Q') {
      while (!(UCSR0A & _BV(UDRE0))) {
      }
      UDR0 = b;
      while (!(UCSR0A & _BV(TXC0))) {
      }
      cli();
      sleep_enable();
      sleep_cpu();
    }
    pwm_pin(&TCCR0A, COM0A1, &OCR0A, &PORTD, PD6, b);
    pwm_pin(&TCCR2A, COM2B1, &OCR2B, &PORTD, PD3, (uint8_t)(255 - b));
    GPIOR0 = 2;
    while (!(UCSR0A & _BV(UDRE0))) {
    }
    UDR0 = b;
  }
}
