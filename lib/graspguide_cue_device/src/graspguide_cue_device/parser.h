// The board's frame parser: bytes in, checked frames out, one byte at a time, with the
// verdicts (and their order: size, CRC, version, id, length) of graspguide_link's
// FrameParser. It stores only what this board decodes (kBufferSize, the largest accepted
// frame, not the schema's largest): a longer frame is still COBS-decoded, CRC-checked and
// sized on the fly, so its trusted header can be answered (per_frame_only, unknown_id,
// bad_length) exactly as a full-solve device answers it.
#pragma once

#include <stddef.h>
#include <stdint.h>

#include "graspguide_cue_device/link_subset.h"
#include "graspguide_cue_device/wire.h"

namespace graspguide {
namespace cue_device {

enum class ParseEvent : uint8_t {
  kNone = 0,  // nothing complete yet (also: a lone delimiter, which is idle line)
  kFrame,     // frame() is a good frame
  kBadCrc,
  kBadCobs,  // the last COBS block was cut short by the delimiter
  kTooLong,  // past the schema's largest frame; the rest up to the delimiter is dropped
  kTooShort,
  kBadVersion,  // frame().header is trusted (its CRC passed): answered with ERROR
  kUnknownId,   // idem
  kBadLength,   // idem
};

struct FrameHeader {
  uint8_t version = 0;
  uint8_t msg_id = 0;
  uint16_t seq = 0;
};

// A checked frame. payload is nullptr when the frame was too large to store (an id this
// board refuses from its header alone).
struct FrameView {
  FrameHeader header;
  const uint8_t* payload = nullptr;
  uint8_t payload_size = 0;
};

class FrameParser {
 public:
  static constexpr size_t kBufferSize =
      link::kHeaderSize + link::kMaxAcceptedPayloadSize + link::kCrcSize;
  static constexpr uint16_t kSchemaMaxRawSize =
      uint16_t(link::kHeaderSize + link::kSchemaMaxPayloadSize + link::kCrcSize);

  ParseEvent push(uint8_t byte) {
    if (byte == 0) return end_of_frame();
    if (dropping_) return ParseEvent::kNone;
    if (started_ && remaining_ > 0) {
      --remaining_;
      return emit(byte);
    }
    // A code byte. The zero the previous block stood for is only known to be data (and
    // not the end of the frame) now that another block follows.
    const bool zero = started_ && zero_pending_;
    started_ = true;
    remaining_ = uint8_t(byte - 1);
    zero_pending_ = byte != 0xFF;
    return zero ? emit(0) : ParseEvent::kNone;
  }

  // The last checked frame: valid after kFrame, kBadVersion, kUnknownId or kBadLength,
  // until the next push().
  const FrameView& frame() const { return frame_; }

  uint32_t good_frames() const { return good_frames_; }
  uint32_t bad_frames() const { return bad_frames_; }

  // Whether bytes of an unfinished frame are held (or being dropped up to a delimiter).
  bool mid_frame() const { return dropping_ || started_; }

  // Forgets a partial frame (e.g. after a long silence on the line); counts nothing.
  void discard_partial() {
    started_ = false;
    dropping_ = false;
    remaining_ = 0;
    zero_pending_ = false;
    size_ = 0;
    crc_ = link::kCrc16Init;
  }

 private:
  // One decoded byte. The CRC runs two bytes behind, so at the delimiter it covers
  // everything but the frame's own CRC, which sits in tail_.
  ParseEvent emit(uint8_t byte) {
    if (size_ >= kSchemaMaxRawSize) {
      dropping_ = true;
      return bad(ParseEvent::kTooLong);
    }
    if (size_ >= 2) crc_ = link::crc16_update(crc_, tail_[size_ & 1u]);
    tail_[size_ & 1u] = byte;
    if (size_ < kBufferSize) buffer_[size_] = byte;
    ++size_;
    return ParseEvent::kNone;
  }

  ParseEvent end_of_frame() {
    const bool was_dropping = dropping_;
    const bool started = started_;
    const bool cut_short = remaining_ != 0;
    const uint16_t size = size_;
    const uint16_t crc = crc_;
    // The CRC's low byte came first: it is the older of the two tail bytes.
    const uint16_t sent_crc = uint16_t(tail_[size & 1u] | (uint16_t(tail_[(size + 1) & 1u]) << 8));
    discard_partial();
    if (was_dropping || !started) return ParseEvent::kNone;
    if (cut_short) return bad(ParseEvent::kBadCobs);
    if (size < link::kHeaderSize + link::kCrcSize) return bad(ParseEvent::kTooShort);
    if (crc != sent_crc) return bad(ParseEvent::kBadCrc);
    frame_ = FrameView{};
    frame_.header.version = buffer_[0];
    frame_.header.msg_id = buffer_[1];
    frame_.header.seq = uint16_t(buffer_[2] | (uint16_t(buffer_[3]) << 8));
    frame_.payload_size = uint8_t(size - link::kHeaderSize - link::kCrcSize);
    if (size <= kBufferSize) frame_.payload = buffer_ + link::kHeaderSize;
    if (frame_.header.version != link::kProtocolVersion) return bad(ParseEvent::kBadVersion);
    size_t expected = 0;
    if (!link::host_payload_size(frame_.header.msg_id, &expected))
      return bad(ParseEvent::kUnknownId);
    if (frame_.payload_size != expected) return bad(ParseEvent::kBadLength);
    ++good_frames_;
    return ParseEvent::kFrame;
  }

  ParseEvent bad(ParseEvent e) {
    ++bad_frames_;
    return e;
  }

  uint8_t buffer_[kBufferSize] = {};
  uint8_t tail_[2] = {0, 0};  // the last two decoded bytes, by size_ parity
  uint16_t size_ = 0;         // decoded bytes of this frame, stored or not
  uint16_t crc_ = link::kCrc16Init;
  uint8_t remaining_ = 0;      // data bytes still to come in the current COBS block
  bool zero_pending_ = false;  // the current block stands for a zero after its data
  bool started_ = false;       // a code byte of this frame was seen
  bool dropping_ = false;      // too long: ignore bytes up to the delimiter
  FrameView frame_;
  uint32_t good_frames_ = 0;
  uint32_t bad_frames_ = 0;
};

}  // namespace cue_device
}  // namespace graspguide
