// Definitions behind the stand-in Arduino API (Arduino.h), and the host entry point a
// real core would provide: enough to link the board code, never run.
#include "Arduino.h"

HardwareSerial Serial;

void pinMode(uint8_t, uint8_t) {}
void digitalWrite(uint8_t, uint8_t) {}
int digitalRead(uint8_t) { return HIGH; }
void analogWrite(uint8_t, int) {}
unsigned long millis() { return 0; }
unsigned long micros() { return 0; }
void delay(unsigned long) {}

#if defined(TEENSYDUINO)
void analogWriteResolution(uint32_t) {}
void analogWriteFrequency(uint8_t, float) {}
#endif

#if defined(ARDUINO_ARCH_ESP32)
#if ESP_ARDUINO_VERSION_MAJOR >= 3
bool ledcAttach(uint8_t, uint32_t, uint8_t) { return true; }
bool ledcWrite(uint8_t, uint32_t) { return true; }
#else
uint32_t ledcSetup(uint8_t, uint32_t frequency_hz, uint8_t) { return frequency_hz; }
void ledcAttachPin(uint8_t, uint8_t) {}
void ledcWrite(uint8_t, uint32_t) {}
#endif
#endif

void setup();
void loop();

int main() {
  setup();
  loop();
  return 0;
}
