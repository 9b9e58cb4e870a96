// libFuzzer target: arbitrary bytes through FrameParser and the generated decoders.
// Built and run by tools/scripts/fuzz_parser.sh (not by pio: this folder is no test_*).
//
// Invariants (any violation aborts, which libFuzzer reports as a crash):
//  * the parser never reads or writes out of bounds (ASan) and never hits UB (UBSan);
//  * every frame it yields has the protocol version, an id it accepts and that id's size;
//  * a frame whose payload decodes re-encodes to a frame that parses back to the same
//    message, with the same seq and byte-identical payload;
//  * the counters add up to the events returned.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <cstring>

#include "graspguide_link/frame.h"
#include "graspguide_link/messages.h"
#include "graspguide_link/parser.h"
#include "graspguide_link/writer.h"

namespace gl = graspguide::link;

namespace {

void require(bool ok) {
  if (!ok) std::abort();
}

// Re-encodes msg, parses the result, and checks it is the same message and payload.
struct Reencode {
  uint16_t seq;
  const uint8_t* payload;
  size_t payload_size;

  template <class Msg>
  void operator()(const Msg& msg) const {
    uint8_t wire[gl::kMaxWireFrameSize];
    size_t n = 0;
    require(gl::write_frame(msg, seq, wire, sizeof wire, &n) == gl::LinkStatus::kOk);
    require(n <= gl::kWireSizeBound<Msg>);
    gl::FrameParser p;
    for (size_t i = 0; i < n; ++i) {
      const gl::ParseEvent e = p.push(wire[i]);
      require(e == (i + 1 == n ? gl::ParseEvent::kFrame : gl::ParseEvent::kNone));
    }
    const gl::FrameView& f = p.frame();
    require(f.header.seq == seq && f.header.msg_id == static_cast<uint8_t>(Msg::kId));
    require(f.payload_size == payload_size && std::memcmp(f.payload, payload, payload_size) == 0);
    Msg back;
    require(gl::read_message(f, &back) == gl::LinkStatus::kOk);
    require(back == msg);
  }
};

void check_frame_roundtrip(const gl::FrameView& f) {
  require(f.header.version == gl::kProtocolVersion);
  size_t expected = 0;
  require(gl::payload_size_of(f.header.msg_id, &expected) && expected == f.payload_size);
  const Reencode re{f.header.seq, f.payload, f.payload_size};
  const gl::LinkStatus s = gl::visit_payload(f.header.msg_id, f.payload, f.payload_size, re);
  // The parser does not check field values; decoders may refuse them, nothing else.
  require(s == gl::LinkStatus::kOk || s == gl::LinkStatus::kBadEnumValue);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  gl::FrameParser parser;
  uint32_t returned[gl::kParseEventCount] = {};
  for (size_t i = 0; i < size; ++i) {
    const gl::ParseEvent e = parser.push(data[i]);
    ++returned[static_cast<size_t>(e)];
    if (e == gl::ParseEvent::kFrame) check_frame_roundtrip(parser.frame());
  }
  uint32_t bad = 0;
  for (size_t e = 1; e < gl::kParseEventCount; ++e) {
    require(parser.event_count(static_cast<gl::ParseEvent>(e)) == returned[e]);
    if (e != static_cast<size_t>(gl::ParseEvent::kFrame)) bad += returned[e];
  }
  require(parser.bad_frames() == bad);
  require(parser.good_frames() == returned[static_cast<size_t>(gl::ParseEvent::kFrame)]);

  // The same bytes as a bare payload of the id in the first byte: decoders alone.
  if (size > 0) {
    const uint8_t id = data[0];
    const uint8_t* payload = data + 1;
    const size_t payload_size = size - 1;
    size_t expected = 0;
    const Reencode re{0x1234, payload, payload_size};
    const gl::LinkStatus s = gl::visit_payload(id, payload, payload_size, re);
    if (!gl::payload_size_of(id, &expected))
      require(s == gl::LinkStatus::kUnknownId);
    else if (expected != payload_size)
      require(s == gl::LinkStatus::kBadLength);
    else
      require(s == gl::LinkStatus::kOk || s == gl::LinkStatus::kBadEnumValue);
  }
  return 0;
}
