// The frame layout, and nothing about particular messages:
//   wire = COBS( version:u8 | msg_id:u8 | seq:u16 LE | payload | crc16:u16 LE ) 0x00
// where the CRC-16/CCITT-FALSE covers version..payload.
#pragma once

#include <cstddef>
#include <cstdint>

#include "graspguide_link/byte_order.h"
#include "graspguide_link/cobs.h"
#include "graspguide_link/crc16.h"
#include "graspguide_link/link_status.h"
#include "graspguide_link/messages.h"

namespace graspguide::link {

inline constexpr uint8_t kFrameDelimiter = 0x00;
inline constexpr size_t kHeaderSize = 4;  // version, msg_id, seq
inline constexpr size_t kCrcSize = 2;
inline constexpr size_t kFrameOverhead = kHeaderSize + kCrcSize;

// Bytes between COBS decoding and the payload: header + payload + CRC.
constexpr size_t raw_frame_size(size_t payload_size) { return kFrameOverhead + payload_size; }
// Bytes on the wire, delimiter included, at most.
constexpr size_t wire_frame_size_bound(size_t payload_size) {
  return cobs_max_encoded_size(raw_frame_size(payload_size)) + 1;
}

inline constexpr size_t kMaxRawFrameSize = raw_frame_size(kMaxPayloadSize);
// A caller's buffer of this size holds any frame this protocol version can write.
inline constexpr size_t kMaxWireFrameSize = wire_frame_size_bound(kMaxPayloadSize);

struct FrameHeader {
  uint8_t version = kProtocolVersion;
  uint8_t msg_id = 0;
  uint16_t seq = 0;
};

// A checked frame; payload points into the buffer that was checked.
struct FrameView {
  FrameHeader header;
  const uint8_t* payload = nullptr;
  size_t payload_size = 0;
};

// Which ids a receiver accepts: a device treats device -> host ids as unknown.
enum class Accept : uint8_t { kAll, kHostToDevice, kDeviceToHost };

constexpr bool accepts(Accept accept, uint8_t msg_id) {
  return accept == Accept::kAll || (accept == Accept::kHostToDevice ? is_host_to_device_id(msg_id)
                                                                    : is_device_to_host_id(msg_id));
}

// Encodes one frame with any header and payload (tests use it to forge bad frames; code
// that sends messages uses write_frame() of writer.h). kTooLong for a payload above
// kMaxPayloadSize, kBufferTooSmall if the frame does not fit in capacity.
inline LinkStatus encode_frame(const FrameHeader& header, const uint8_t* payload,
                               size_t payload_size, uint8_t* out, size_t capacity,
                               size_t* written) {
  if (payload_size > kMaxPayloadSize) return LinkStatus::kTooLong;
  uint8_t raw[kMaxRawFrameSize];
  store_u8(raw + 0, header.version);
  store_u8(raw + 1, header.msg_id);
  store_u16(raw + 2, header.seq);
  for (size_t i = 0; i < payload_size; ++i) raw[kHeaderSize + i] = payload[i];
  const size_t crc_at = kHeaderSize + payload_size;
  store_u16(raw + crc_at, crc16(raw, crc_at));
  size_t encoded = 0;
  const LinkStatus status = cobs_encode(raw, crc_at + kCrcSize, out, capacity, &encoded);
  if (status != LinkStatus::kOk) return status;
  if (encoded >= capacity) return LinkStatus::kBufferTooSmall;
  out[encoded] = kFrameDelimiter;
  *written = encoded + 1;
  return LinkStatus::kOk;
}

// Checks one COBS-decoded frame, in the order that makes each verdict trustworthy: size,
// CRC (before any header field is believed), version, id, payload size.
inline LinkStatus check_frame(const uint8_t* raw, size_t size, Accept accept, FrameView* out) {
  if (size < kFrameOverhead) return LinkStatus::kTooShort;
  if (size > kMaxRawFrameSize) return LinkStatus::kTooLong;
  const size_t crc_at = size - kCrcSize;
  if (crc16(raw, crc_at) != load_u16(raw + crc_at)) return LinkStatus::kBadCrc;
  FrameView view;
  view.header.version = load_u8(raw + 0);
  view.header.msg_id = load_u8(raw + 1);
  view.header.seq = load_u16(raw + 2);
  view.payload = raw + kHeaderSize;
  view.payload_size = crc_at - kHeaderSize;
  // The header is trustworthy from here on, so the caller may answer with ERROR + seq.
  *out = view;
  if (view.header.version != kProtocolVersion) return LinkStatus::kBadVersion;
  size_t expected = 0;
  if (!accepts(accept, view.header.msg_id) || !payload_size_of(view.header.msg_id, &expected))
    return LinkStatus::kUnknownId;
  if (view.payload_size != expected) return LinkStatus::kBadLength;
  return LinkStatus::kOk;
}

}  // namespace graspguide::link
