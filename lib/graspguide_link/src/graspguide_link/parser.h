// FrameParser: turns a byte stream into checked frames, one byte at a time. It never
// blocks, never allocates, holds at most one decoded frame, and after any error drops
// bytes up to the next 0x00 delimiter, so one bad frame costs only itself.
#pragma once

#include <cstddef>
#include <cstdint>

#include "graspguide_link/cobs.h"
#include "graspguide_link/frame.h"
#include "graspguide_link/link_status.h"
#include "graspguide_link/messages.h"

namespace graspguide::link {

enum class ParseEvent : uint8_t {
  kNone = 0,  // nothing complete yet (also: an empty frame, i.e. a lone delimiter)
  kFrame,     // frame() is a good frame
  kBadCrc,
  kBadCobs,  // the last COBS block was cut short by the delimiter
  kTooLong,  // reported when the buffer overflows; the rest of the frame is dropped
  kTooShort,
  kBadVersion,  // frame().header is valid (its CRC passed): answer ERROR with its seq
  kUnknownId,   // idem
  kBadLength,   // idem
};
inline constexpr size_t kParseEventCount = static_cast<size_t>(ParseEvent::kBadLength) + 1;

// The ERROR code a device reports for each event, by ParseEvent value (kOk: none). The
// error events share their names with these codes.
inline constexpr ErrorCode kParseEventErrors[kParseEventCount] = {
    ErrorCode::kOk,         ErrorCode::kOk,        ErrorCode::kBadCrc,
    ErrorCode::kBadCobs,    ErrorCode::kTooLong,   ErrorCode::kTooShort,
    ErrorCode::kBadVersion, ErrorCode::kUnknownId, ErrorCode::kBadLength,
};

constexpr const char* parse_event_name(ParseEvent e) {
  const size_t i = static_cast<size_t>(e);
  if (e == ParseEvent::kNone) return "none";
  if (e == ParseEvent::kFrame) return "frame";
  return i < kParseEventCount ? enum_name(kParseEventErrors[i]) : "unknown";
}

// The ERROR code a device reports for a parse event; false for kNone and kFrame.
constexpr bool error_code_for(ParseEvent e, ErrorCode* code) {
  const size_t i = static_cast<size_t>(e);
  if (i >= kParseEventCount || kParseEventErrors[i] == ErrorCode::kOk) return false;
  *code = kParseEventErrors[i];
  return true;
}

// Whether a parse event leaves a header that can be trusted (answerable with ERROR).
constexpr bool has_trusted_header(ParseEvent e) {
  return e == ParseEvent::kFrame || e == ParseEvent::kBadVersion || e == ParseEvent::kUnknownId ||
         e == ParseEvent::kBadLength;
}

class FrameParser {
 public:
  // Decoded bytes of the largest frame: anything longer is too_long.
  static constexpr size_t kBufferSize = kMaxRawFrameSize;

  explicit FrameParser(Accept accept = Accept::kAll) : accept_(accept) {}

  // Feeds one byte. Everything but kNone is counted; see ParseEvent for what frame() holds.
  ParseEvent push(uint8_t byte) {
    if (byte == kFrameDelimiter) return end_of_frame();
    if (dropping_) return ParseEvent::kNone;
    if (cobs_.push(byte, buffer_, kBufferSize, &size_) != LinkStatus::kOk) {
      dropping_ = true;
      return count(ParseEvent::kTooLong);
    }
    return ParseEvent::kNone;
  }

  // The last checked frame: valid after an event with has_trusted_header(), until the
  // next push().
  const FrameView& frame() const { return frame_; }

  uint32_t good_frames() const { return counts_[static_cast<size_t>(ParseEvent::kFrame)]; }
  uint32_t bad_frames() const { return bad_frames_; }
  uint32_t event_count(ParseEvent e) const { return counts_[static_cast<size_t>(e)]; }

  // Whether bytes of an unfinished frame are held (or being dropped up to a delimiter).
  bool mid_frame() const { return dropping_ || cobs_.started(); }

  // Forgets a partial frame (e.g. after a long silence on the line); counts nothing.
  void discard_partial() {
    cobs_.reset();
    size_ = 0;
    dropping_ = false;
  }

  void reset_counters() {
    for (uint32_t& c : counts_) c = 0;
    bad_frames_ = 0;
  }

 private:
  ParseEvent end_of_frame() {
    const bool was_dropping = dropping_;
    const bool started = cobs_.started();
    const LinkStatus cobs_status = cobs_.finish();
    const size_t size = size_;
    discard_partial();
    // A dropped frame was already reported; a lone delimiter is idle line, not a frame.
    if (was_dropping || !started) return ParseEvent::kNone;
    if (cobs_status != LinkStatus::kOk) return count(ParseEvent::kBadCobs);
    // buffer_ stays intact until the next push, so frame_ may point into it.
    return count(event_of(check_frame(buffer_, size, accept_, &frame_)));
  }

  // The event that reports each verdict of check_frame, by LinkStatus value: the error
  // events are named after the verdicts.
  static constexpr ParseEvent event_of(LinkStatus verdict) {
    constexpr ParseEvent kByVerdict[] = {
        ParseEvent::kFrame,       // kOk
        ParseEvent::kTooLong,     // kBufferTooSmall (not a verdict of check_frame)
        ParseEvent::kBadCobs,     // kBadCobs (idem: the COBS decoder reports it)
        ParseEvent::kTooLong,     // kTooLong
        ParseEvent::kTooShort,    // kTooShort
        ParseEvent::kBadCrc,      // kBadCrc
        ParseEvent::kBadVersion,  // kBadVersion
        ParseEvent::kUnknownId,   // kUnknownId
        ParseEvent::kBadLength,   // kBadLength
    };
    static_assert(static_cast<size_t>(LinkStatus::kBadLength) + 1 ==
                      sizeof(kByVerdict) / sizeof(kByVerdict[0]),
                  "one event per LinkStatus up to kBadLength");
    const size_t i = static_cast<size_t>(verdict);
    return i <= static_cast<size_t>(LinkStatus::kBadLength) ? kByVerdict[i] : ParseEvent::kTooLong;
  }

  ParseEvent count(ParseEvent e) {
    ++counts_[static_cast<size_t>(e)];
    if (e != ParseEvent::kFrame) ++bad_frames_;
    return e;
  }

  uint8_t buffer_[kBufferSize] = {};
  size_t size_ = 0;
  CobsStreamDecoder cobs_;
  bool dropping_ = false;  // an error was reported: ignore bytes up to the delimiter
  Accept accept_;
  FrameView frame_;
  uint32_t counts_[kParseEventCount] = {};
  uint32_t bad_frames_ = 0;
};

// Unpacks the frame's payload into Msg: kWrongMessage if the frame holds another id.
template <class Msg>
LinkStatus read_message(const FrameView& frame, Msg* out, uint8_t* bad_field = nullptr) {
  if (frame.header.msg_id != static_cast<uint8_t>(Msg::kId)) return LinkStatus::kWrongMessage;
  return unpack(frame.payload, frame.payload_size, out, bad_field);
}

}  // namespace graspguide::link
