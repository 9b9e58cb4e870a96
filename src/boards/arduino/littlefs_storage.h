// The ESP32 boards' non-volatile store for the host-less mode (the plan and the results log):
// one file of fixed size on the flash's LittleFS partition, through the Arduino-ESP32 core's
// FS API. LittleFS copies on write and commits each file sync atomically, so a power cut
// during a write leaves the file as it was before that write or after it; the log's commit
// byte and CRC (results_log.h) still guard the case where it does not.
#pragma once

#include <FS.h>
#include <LittleFS.h>

#include "graspguide_device/nv_storage.h"

namespace graspguide::board {

class LittleFsStorage final : public device::NvStorage {
 public:
  // path: absolute inside the partition, e.g. "/graspguide.bin". size_bytes: the file's size
  // when this creates it.
  LittleFsStorage(const char* path, uint32_t size_bytes) : path_(path), size_(size_bytes) {}

  // Mounts the partition and opens the file, creating it erased (every byte 0xFF, as
  // NvStorage promises) when missing. False: no usable store; size_bytes() is then 0, so the
  // plan and the log report "too small" and every host-less request fails with a storage
  // error instead of pretending to store.
  bool begin() {
    // A partition that never held a LittleFS (a new board, or one last used with SPIFFS)
    // does not mount; it is formatted once. A LittleFS that was mounted before survives
    // power cuts by design, so this does not wipe a study's records after a brown-out.
    if (!LittleFS.begin(/*formatOnFail=*/true)) return false;
    if (!LittleFS.exists(path_)) {
      File created = LittleFS.open(path_, FILE_WRITE);
      if (!created) return false;
      created.close();
    }
    file_ = LittleFS.open(path_, "r+");
    if (!file_) return false;
    const uint32_t have = uint32_t(file_.size());
    // A file larger than asked (a build with a bigger store) is kept whole: cutting it would
    // drop records. A shorter one (creation cut by a power loss) is completed: its missing
    // tail was never written, so it is erased by definition.
    if (have > size_) size_ = have;
    if (have < size_ && !fill_erased(have)) {
      file_.close();
      return false;
    }
    open_ = true;
    return true;
  }

  uint32_t size_bytes() const override { return open_ ? size_ : 0; }

  bool read(uint32_t offset, uint8_t* out, uint32_t n) override {
    if (!open_ || !device::nv_range_ok(size_, offset, n)) return false;
    if (!file_.seek(offset)) return false;
    return file_.read(out, n) == n;
  }

  // flush() reaches fsync, which commits the write to flash before this returns. The core's
  // flush() reports no failure; a sync that failed shows at the next mount as a torn record,
  // which the log skips and counts.
  bool write(uint32_t offset, const uint8_t* data, uint32_t n) override {
    if (!open_ || !device::nv_range_ok(size_, offset, n)) return false;
    if (!file_.seek(offset)) return false;
    const bool whole = file_.write(data, n) == n;
    file_.flush();
    return whole;
  }

 private:
  // 0xFF from byte `from` to the end, a stack-sized chunk at a time.
  bool fill_erased(uint32_t from) {
    static constexpr uint32_t kChunkBytes = 256;
    uint8_t erased[kChunkBytes];
    for (uint32_t i = 0; i < kChunkBytes; ++i) erased[i] = 0xFF;
    if (!file_.seek(from)) return false;
    for (uint32_t at = from; at < size_;) {
      const uint32_t n = size_ - at < kChunkBytes ? size_ - at : kChunkBytes;
      if (file_.write(erased, n) != n) return false;
      at += n;
    }
    file_.flush();
    return true;
  }

  const char* path_;
  uint32_t size_;
  File file_;
  bool open_ = false;
};

}  // namespace graspguide::board
