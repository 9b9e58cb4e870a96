// Definitions behind the stand-in FS and LittleFS (ESP32 only, as in the real cores): enough
// to link, never run. The mount fails, as on a board whose flash has no file system
// partition.
#if defined(ARDUINO_ARCH_ESP32)
#include "LittleFS.h"

fs::LittleFSFS LittleFS;

namespace fs {

size_t File::read(uint8_t*, size_t) { return 0; }
size_t File::write(const uint8_t*, size_t) { return 0; }
void File::flush() {}
bool File::seek(uint32_t, SeekMode) { return false; }
size_t File::size() const { return 0; }
void File::close() {}
File::operator bool() const { return false; }

File FS::open(const char*, const char*, const bool) { return File(); }
bool FS::exists(const char*) { return false; }

bool LittleFSFS::begin(bool, const char*, uint8_t, const char*) { return false; }

}  // namespace fs
#endif
