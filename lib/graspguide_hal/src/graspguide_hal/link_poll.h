// The receive half of a device's poll, the same for both device libraries: what the stream
// has goes through the link's parser, and a frame the host left half-sent is dropped.
#pragma once

#include <stddef.h>
#include <stdint.h>

#include "graspguide_hal/hal.h"

// A frame's bytes arrive together (a 92-byte POSE takes 8 ms at 115200 baud); a partial
// frame followed by this much silence is dropped, so whatever comes next (a STOP from a
// host that gave up mid-frame) starts clean even without the leading delimiter.
#ifndef GRASPGUIDE_PARTIAL_FRAME_TIMEOUT_MS
#define GRASPGUIDE_PARTIAL_FRAME_TIMEOUT_MS 50
#endif

namespace graspguide {
namespace hal {

constexpr uint32_t kPartialFrameTimeoutUs = uint32_t(GRASPGUIDE_PARTIAL_FRAME_TIMEOUT_MS) * 1000u;

// The poll loop's receive half for a device, which befriends LinkPoll and has link_stream(),
// link_clock(), link_parser() (push(byte) -> event, mid_frame(), discard_partial()) and
// on_link_event(event).
class LinkPoll {
 public:
  // Reads what the stream has, kChunkBytes at a time, hands each byte to the parser and
  // each event to the device. Then, at the clock's time after reading (now_us), drops a
  // partial frame that has had no byte for kPartialFrameTimeoutUs. Returns the number of
  // bytes read. Always inlined, reaching each part through the device: it is each device's
  // one poll loop, and a call, or the parts held apart, would cost the Pro Mini flash.
  template <size_t kChunkBytes, class Device>
  __attribute__((always_inline)) inline size_t receive(Device& device, uint32_t& now_us) {
    uint8_t chunk[kChunkBytes];
    size_t total = 0;
    for (;;) {
      const size_t n = device.link_stream().read(chunk, sizeof chunk);
      for (size_t i = 0; i < n; ++i) device.on_link_event(device.link_parser().push(chunk[i]));
      total += n;
      if (n < sizeof chunk) break;
    }
    now_us = device.link_clock().now_us();
    if (total > 0) {
      last_byte_us_ = now_us;
    } else if (device.link_parser().mid_frame() &&
               now_us - last_byte_us_ >= kPartialFrameTimeoutUs) {
      device.link_parser().discard_partial();
    }
    return total;
  }

 private:
  uint32_t last_byte_us_ = 0;
};

}  // namespace hal
}  // namespace graspguide
