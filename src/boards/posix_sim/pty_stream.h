// The simulated device's serial port: the master side of a pseudo-terminal, so host tools
// open the slave path with pyserial exactly as they open a board's port.
//
// Both directions are buffered so that a host streaming POSEs costs few system calls: a
// read takes everything the pty holds at once (LinkDevice asks for 64 bytes at a time), and
// the frames written while one poll() handles that input go out together at flush(). The
// main loop flushes after every poll(), so the device answers as before, only in fewer
// write calls; a frame is never held back across a wait for input.
#pragma once

#include <cstddef>
#include <string>

#include "graspguide_hal/hal.h"

namespace graspguide::sim {

class PtyStream final : public graspguide::hal::ByteStream {
 public:
  PtyStream() = default;
  PtyStream(const PtyStream&) = delete;
  PtyStream& operator=(const PtyStream&) = delete;
  ~PtyStream();

  // Opens the pair in raw mode; false (with errno kept) when the system refuses.
  bool open();
  const std::string& slave_path() const { return slave_path_; }
  int fd() const { return master_fd_; }

  // Waits up to timeout_ms for input; true when bytes can be read (or are buffered).
  bool wait_readable(int timeout_ms) const;

  size_t read(uint8_t* buffer, size_t capacity) override;
  // Queues one whole frame for flush(); flushes first when it would not fit.
  size_t write(const uint8_t* data, size_t length) override;
  // Writes every queued frame, in as few write calls as the pty takes.
  void flush();

 private:
  // What the pty buffers hold at most in one direction: more is never there at once.
  static constexpr size_t kBufferSize = 4096;
  // The frames queued are cut at these offsets (each frame's end), so a host that stops
  // reading loses whole frames, as when each frame had its own write.
  static constexpr size_t kMaxQueuedFrames = kBufferSize / 8;

  void write_frame(const uint8_t* data, size_t length, size_t sent);

  int master_fd_ = -1;
  int slave_keepalive_fd_ = -1;  // keeps the pty alive between host connections
  std::string slave_path_;
  uint8_t in_[kBufferSize];
  size_t in_begin_ = 0;
  size_t in_end_ = 0;
  uint8_t out_[kBufferSize];
  size_t out_size_ = 0;
  size_t frame_ends_[kMaxQueuedFrames];
  size_t frames_ = 0;
};

}  // namespace graspguide::sim
