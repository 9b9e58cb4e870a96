// Status of every fallible link operation (encode, decode, pack, unpack).
#pragma once

#include <cstdint>

namespace graspguide_link {

enum class LinkStatus : uint8_t {
  kOk = 0,
  kBufferTooSmall,  // the caller's output buffer cannot hold the result
  kBadCobs,         // a COBS block runs past the end, or a 0x00 sits inside the data
  kTooLong,         // more bytes than the largest frame can have
  kTooShort,        // fewer bytes than header + CRC
  kBadCrc,
  kBadVersion,    // CRC fine, but another protocol version
  kUnknownId,     // CRC fine, but no message (accepted here) has this id
  kBadLength,     // CRC fine, but the payload size does not match the id
  kBadEnumValue,  // an enum, bool or ascii field outside its declared set
  kWrongMessage,  // asked to read a message of one type from a frame of another
};

constexpr const char* link_status_name(LinkStatus s) {
  switch (s) {
    case LinkStatus::kOk:
      return "ok";
    case LinkStatus::kBufferTooSmall:
      return "buffer_too_small";
    case LinkStatus::kBadCobs:
      return "bad_cobs";
    case LinkStatus::kTooLong:
      return "too_long";
    case LinkStatus::kTooShort:
      return "too_short";
    case LinkStatus::kBadCrc:
      return "bad_crc";
    case LinkStatus::kBadVersion:
      return "bad_version";
    case LinkStatus::kUnknownId:
      return "unknown_id";
    case LinkStatus::kBadLength:
      return "bad_length";
    case LinkStatus::kBadEnumValue:
      return "bad_enum_value";
    case LinkStatus::kWrongMessage:
      return "wrong_message";
  }
  return "unknown";
}

}  // namespace graspguide_link
