// Stand-in for the ESP32 core's LittleFS library (LittleFS.h): the mount
// src/boards/arduino/littlefs_storage.h makes, with the core's signature and defaults
// (Arduino.h says what this proves).
#pragma once

#include "FS.h"

namespace fs {

class LittleFSFS final : public FS {
 public:
  bool begin(bool formatOnFail = false, const char* basePath = "/littlefs",
             uint8_t maxOpenFiles = 10, const char* partitionLabel = "spiffs");
};

}  // namespace fs

extern fs::LittleFSFS LittleFS;
