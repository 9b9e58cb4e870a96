// Status of every fallible link operation (encode, decode, pack, unpack).
#pragma once

#include <cstddef>
#include <cstdint>

namespace graspguide::link {

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

inline constexpr const char* kLinkStatusNames[] = {
    "ok",          "buffer_too_small", "bad_cobs",   "too_long",       "too_short",     "bad_crc",
    "bad_version", "unknown_id",       "bad_length", "bad_enum_value", "wrong_message",
};
static_assert(sizeof kLinkStatusNames / sizeof kLinkStatusNames[0] ==
                  static_cast<size_t>(LinkStatus::kWrongMessage) + 1,
              "one name per LinkStatus");

constexpr const char* link_status_name(LinkStatus s) {
  const size_t i = static_cast<size_t>(s);
  return i < sizeof kLinkStatusNames / sizeof kLinkStatusNames[0] ? kLinkStatusNames[i] : "unknown";
}

}  // namespace graspguide::link
