// Stand-in for the ESP32 core's FS library (FS.h): the File calls
// src/boards/arduino/littlefs_storage.h makes, with the core's signatures (Arduino.h says
// what this proves). Only the ESP32 core has it, so including it elsewhere is an error here.
#pragma once

#if !defined(ARDUINO_ARCH_ESP32)
#error "FS.h is the ESP32 core's file system API; this board has none"
#endif

#include "Arduino.h"

namespace fs {

#define FILE_READ "r"
#define FILE_WRITE "w"
#define FILE_APPEND "a"

enum SeekMode { SeekSet = 0, SeekCur = 1, SeekEnd = 2 };

// The core's File is a handle to a shared implementation, copied by value.
class File final : public Stream {
 public:
  int read() override { return -1; }
  size_t read(uint8_t* buf, size_t size);
  size_t write(const uint8_t* buf, size_t size) override;
  void flush();
  bool seek(uint32_t pos, SeekMode mode);
  bool seek(uint32_t pos) { return seek(pos, SeekSet); }
  size_t size() const;
  void close();
  operator bool() const;
};

class FS {
 public:
  File open(const char* path, const char* mode = FILE_READ, const bool create = false);
  bool exists(const char* path);
};

}  // namespace fs

using fs::File;
using fs::FS;
using fs::SeekCur;
using fs::SeekEnd;
using fs::SeekMode;
using fs::SeekSet;
