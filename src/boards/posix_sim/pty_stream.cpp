#include "pty_stream.h"

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>

namespace graspguide::sim {

PtyStream::~PtyStream() {
  if (slave_keepalive_fd_ >= 0) ::close(slave_keepalive_fd_);
  if (master_fd_ >= 0) ::close(master_fd_);
}

bool PtyStream::open() {
  master_fd_ = ::posix_openpt(O_RDWR | O_NOCTTY | O_NONBLOCK);
  if (master_fd_ < 0 || ::grantpt(master_fd_) != 0 || ::unlockpt(master_fd_) != 0) return false;
  const char* name = ::ptsname(master_fd_);
  if (name == nullptr) return false;
  slave_path_ = name;
  // Raw mode on the slave: binary frames must pass unchanged (no echo, no CR/LF mapping).
  slave_keepalive_fd_ = ::open(name, O_RDWR | O_NOCTTY | O_NONBLOCK);
  if (slave_keepalive_fd_ < 0) return false;
  termios tio{};
  if (::tcgetattr(slave_keepalive_fd_, &tio) != 0) return false;
  ::cfmakeraw(&tio);
  return ::tcsetattr(slave_keepalive_fd_, TCSANOW, &tio) == 0;
}

bool PtyStream::wait_readable(int timeout_ms) const {
  pollfd p{master_fd_, POLLIN, 0};
  return ::poll(&p, 1, timeout_ms) > 0 && (p.revents & POLLIN);
}

size_t PtyStream::read(uint8_t* buffer, size_t capacity) {
  const ssize_t n = ::read(master_fd_, buffer, capacity);
  return n > 0 ? static_cast<size_t>(n) : 0;
}

size_t PtyStream::write(const uint8_t* data, size_t length) {
  // LinkDevice writes one whole frame per call. A host that stops reading for
  // kWriteTimeoutMs loses this frame; if part of it went out, a delimiter ends it there, so
  // the host's parser drops only this frame instead of merging it with the next.
  constexpr int kWriteTimeoutMs = 200;
  size_t done = 0;
  while (done < length) {
    const ssize_t n = ::write(master_fd_, data + done, length - done);
    if (n > 0) {
      done += static_cast<size_t>(n);
      continue;
    }
    pollfd p{master_fd_, POLLOUT, 0};
    if (!(n < 0 && errno == EAGAIN) || ::poll(&p, 1, kWriteTimeoutMs) <= 0) break;
  }
  if (done > 0 && done < length) {
    const uint8_t delimiter = 0;
    pollfd p{master_fd_, POLLOUT, 0};
    if (::poll(&p, 1, kWriteTimeoutMs) > 0) (void)::write(master_fd_, &delimiter, 1);
  }
  return done;
}

}  // namespace graspguide::sim
