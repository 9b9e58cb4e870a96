// Consistent Overhead Byte Stuffing: removes every 0x00 from a frame so that 0x00 can
// delimit frames, at a cost of one byte per 254 (docs/protocol.md, "Framing").
// Encoding rule shared with the Python side and the golden-frame generator: a block of
// 254 data bytes that ends the input gets no extra 0x01 code after it.
#pragma once

#include <cstddef>
#include <cstdint>

#include "graspguide_link/link_status.h"

namespace graspguide::link {

inline constexpr uint8_t kCobsMaxCode = 0xFF;  // a block of 254 data bytes, no zero
inline constexpr size_t kCobsMaxBlockData = 254;

// Upper bound of the encoded size of `size` bytes (without the 0x00 delimiter).
constexpr size_t cobs_max_encoded_size(size_t size) { return size + size / kCobsMaxBlockData + 1; }

// Encodes in[0..size) into out; *written is the encoded size. kBufferTooSmall if it does
// not fit in capacity (out is then partly written).
inline LinkStatus cobs_encode(const uint8_t* in, size_t size, uint8_t* out, size_t capacity,
                              size_t* written) {
  size_t w = 0;
  size_t i = 0;
  for (;;) {
    const size_t code_at = w++;
    if (code_at >= capacity) return LinkStatus::kBufferTooSmall;
    size_t block = 0;
    while (i < size && in[i] != 0 && block < kCobsMaxBlockData) {
      if (w >= capacity) return LinkStatus::kBufferTooSmall;
      out[w++] = in[i++];
      ++block;
    }
    out[code_at] = static_cast<uint8_t>(block + 1);
    if (block == kCobsMaxBlockData) {
      if (i == size) break;
      continue;  // a full block stands for no zero: the next block starts at in[i]
    }
    if (i == size) break;
    ++i;              // the zero this block stands for
    if (i == size) {  // that zero was the last byte: an empty final block
      if (w >= capacity) return LinkStatus::kBufferTooSmall;
      out[w++] = 1;
      break;
    }
  }
  *written = w;
  return LinkStatus::kOk;
}

// Decodes one encoded frame (without its delimiter). kBadCobs for an empty input, a 0x00
// in the input, or a block that runs past the end; kBufferTooSmall if out is too small.
inline LinkStatus cobs_decode(const uint8_t* in, size_t size, uint8_t* out, size_t capacity,
                              size_t* written) {
  if (size == 0) return LinkStatus::kBadCobs;
  size_t w = 0;
  size_t i = 0;
  while (i < size) {
    const uint8_t code = in[i++];
    if (code == 0) return LinkStatus::kBadCobs;
    const size_t data = static_cast<size_t>(code) - 1;
    if (data > size - i) return LinkStatus::kBadCobs;
    for (size_t k = 0; k < data; ++k) {
      if (in[i] == 0) return LinkStatus::kBadCobs;
      if (w >= capacity) return LinkStatus::kBufferTooSmall;
      out[w++] = in[i++];
    }
    if (code != kCobsMaxCode && i < size) {
      if (w >= capacity) return LinkStatus::kBufferTooSmall;
      out[w++] = 0;
    }
  }
  *written = w;
  return LinkStatus::kOk;
}

// The same decoding one byte at a time, for a parser that sees the stream byte by byte
// and must never hold more than one decoded frame. The caller owns the output buffer.
class CobsStreamDecoder {
 public:
  // One non-zero byte of an encoded frame. Appends at most one byte to out[*size];
  // kBufferTooSmall (nothing appended) when that would pass capacity.
  LinkStatus push(uint8_t byte, uint8_t* out, size_t capacity, size_t* size) {
    if (started_ && remaining_ > 0) {
      if (*size >= capacity) return LinkStatus::kBufferTooSmall;
      out[(*size)++] = byte;
      --remaining_;
      return LinkStatus::kOk;
    }
    // A code byte. The zero the previous block stood for is only known to be data (and
    // not the end of the frame) now that another block follows.
    if (started_ && zero_pending_) {
      if (*size >= capacity) return LinkStatus::kBufferTooSmall;
      out[(*size)++] = 0;
    }
    started_ = true;
    remaining_ = static_cast<uint8_t>(byte - 1);
    zero_pending_ = byte != kCobsMaxCode;
    return LinkStatus::kOk;
  }

  // At the 0x00 delimiter: kBadCobs if the last block is cut short (a truncated frame).
  LinkStatus finish() const { return remaining_ == 0 ? LinkStatus::kOk : LinkStatus::kBadCobs; }

  bool started() const { return started_; }

  void reset() {
    remaining_ = 0;
    zero_pending_ = false;
    started_ = false;
  }

 private:
  uint8_t remaining_ = 0;      // data bytes still to come in the current block
  bool zero_pending_ = false;  // the current block stands for a zero after its data
  bool started_ = false;       // a code byte of this frame was seen
};

}  // namespace graspguide::link
