// A fixed line buffer with integer formatting: one semihosting call per line keeps the
// emulator's time out of the counted regions and needs no printf.
#pragma once

#include <cstddef>
#include <cstdint>

namespace stages {

class LineBuffer {
 public:
  LineBuffer& str(const char* s) {
    while (*s && n_ + 2 < sizeof buf_) buf_[n_++] = *s++;
    return *this;
  }
  LineBuffer& num(int64_t v) {
    char tmp[24];
    int i = 0;
    const bool neg = v < 0;
    uint64_t u = neg ? uint64_t(-(v + 1)) + 1 : uint64_t(v);
    do {
      tmp[i++] = char('0' + u % 10);
      u /= 10;
    } while (u);
    if (neg) tmp[i++] = '-';
    while (i && n_ + 2 < sizeof buf_) buf_[n_++] = tmp[--i];
    return *this;
  }
  LineBuffer& sp() { return str(" "); }
  // Terminates the line and returns it; the buffer starts over.
  const char* end() {
    buf_[n_++] = '\n';
    buf_[n_] = '\0';
    n_ = 0;
    return buf_;
  }

 private:
  char buf_[512];
  size_t n_ = 0;
};

}  // namespace stages
