// The simulated device's serial port: the master side of a pseudo-terminal, so host tools
// open the slave path with pyserial exactly as they open a board's port.
#pragma once

#include <string>

#include "graspguide_device/hal.h"

namespace graspguide::sim {

class PtyStream final : public device::ByteStream {
 public:
  PtyStream() = default;
  PtyStream(const PtyStream&) = delete;
  PtyStream& operator=(const PtyStream&) = delete;
  ~PtyStream();

  // Opens the pair in raw mode; false (with errno kept) when the system refuses.
  bool open();
  const std::string& slave_path() const { return slave_path_; }
  int fd() const { return master_fd_; }

  // Waits up to timeout_ms for input; true when bytes can be read.
  bool wait_readable(int timeout_ms) const;

  size_t read(uint8_t* buffer, size_t capacity) override;
  size_t write(const uint8_t* data, size_t length) override;

 private:
  int master_fd_ = -1;
  int slave_keepalive_fd_ = -1;  // keeps the pty alive between host connections
  std::string slave_path_;
};

}  // namespace graspguide::sim
