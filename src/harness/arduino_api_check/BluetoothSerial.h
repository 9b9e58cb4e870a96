// Stand-in for the ESP32 core's BluetoothSerial (Arduino.h says why and what it proves).
#pragma once

#include "Arduino.h"

class BluetoothSerial final : public Stream {
 public:
  bool begin(const char* /*name*/) { return true; }
};
