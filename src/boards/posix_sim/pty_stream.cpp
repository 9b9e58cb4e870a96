#include "pty_stream.h"

#include <fcntl.h>
#include <poll.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>

namespace graspguide::sim {

PtyStream::~PtyStream() {
  flush();
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
  if (in_begin_ < in_end_) return true;
  pollfd p{master_fd_, POLLIN, 0};
  return ::poll(&p, 1, timeout_ms) > 0 && (p.revents & POLLIN);
}

size_t PtyStream::read(uint8_t* buffer, size_t capacity) {
  if (in_begin_ == in_end_) {
    const ssize_t n = ::read(master_fd_, in_, sizeof in_);
    if (n <= 0) return 0;
    in_begin_ = 0;
    in_end_ = static_cast<size_t>(n);
  }
  const size_t n = in_end_ - in_begin_ < capacity ? in_end_ - in_begin_ : capacity;
  std::memcpy(buffer, in_ + in_begin_, n);
  in_begin_ += n;
  return n;
}

size_t PtyStream::write(const uint8_t* data, size_t length) {
  if (length > sizeof out_) {  // never for a frame of this protocol; sent on its own
    flush();
    write_frame(data, length, 0);
    return length;
  }
  if (out_size_ + length > sizeof out_ || frames_ == kMaxQueuedFrames) flush();
  std::memcpy(out_ + out_size_, data, length);
  out_size_ += length;
  frame_ends_[frames_++] = out_size_;
  return length;
}

void PtyStream::flush() {
  // One write for all the queued frames when the pty takes them (it does unless the host
  // stopped reading); else frame by frame, each with write_frame's timeout.
  size_t done = 0;
  if (out_size_ > 0) {
    const ssize_t n = ::write(master_fd_, out_, out_size_);
    if (n > 0) done = static_cast<size_t>(n);
  }
  size_t start = 0;
  for (size_t i = 0; i < frames_ && done < out_size_; ++i) {
    const size_t end = frame_ends_[i];
    if (end > done) {
      const size_t sent = done > start ? done - start : 0;
      write_frame(out_ + start + sent, end - start - sent, sent);
      done = end;
    }
    start = end;
  }
  out_size_ = 0;
  frames_ = 0;
}

void PtyStream::write_frame(const uint8_t* data, size_t length, size_t sent) {
  // A host that stops reading for kWriteTimeoutMs loses this frame; if part of it went out
  // (``sent`` bytes before this call, or some now), a delimiter ends it there, so the
  // host's parser drops only this frame instead of merging it with the next.
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
  if (sent + done > 0 && done < length) {
    const uint8_t delimiter = 0;
    pollfd p{master_fd_, POLLOUT, 0};
    if (::poll(&p, 1, kWriteTimeoutMs) > 0) (void)::write(master_fd_, &delimiter, 1);
  }
}

}  // namespace graspguide::sim
