// Encodes typed messages into a caller's fixed buffer, and numbers them.
#pragma once

#include <cstddef>
#include <cstdint>

#include "graspguide_link/frame.h"
#include "graspguide_link/link_status.h"
#include "graspguide_link/messages.h"

namespace graspguide::link {

// Bytes on the wire of Msg, at most (delimiter included): size a buffer for one message.
template <class Msg>
inline constexpr size_t kWireSizeBound = wire_frame_size_bound(Msg::kPayloadSize);

// Writes Msg as one complete frame (delimiter included) into out. kBadEnumValue if a
// field holds a value no decoder accepts, kBufferTooSmall if the frame does not fit.
template <class Msg>
LinkStatus write_frame(const Msg& msg, uint16_t seq, uint8_t* out, size_t capacity,
                       size_t* written) {
  static_assert(Msg::kPayloadSize <= kMaxPayloadSize, "generated sizes disagree");
  uint8_t payload[kMaxPayloadSize] = {};
  size_t payload_size = 0;
  const LinkStatus status = pack(msg, payload, sizeof payload, &payload_size);
  if (status != LinkStatus::kOk) return status;
  FrameHeader header;
  header.msg_id = static_cast<uint8_t>(Msg::kId);
  header.seq = seq;
  return encode_frame(header, payload, payload_size, out, capacity, written);
}

// The sender's frame counter: the host numbers its requests with it, the device its own
// frames (replies echo the request's seq in their payload, not in the header).
class SequenceCounter {
 public:
  // The seq for the next frame; wraps from 0xFFFF to 0.
  uint16_t next() { return next_++; }
  uint16_t peek() const { return next_; }

 private:
  uint16_t next_ = 0;
};

}  // namespace graspguide::link
