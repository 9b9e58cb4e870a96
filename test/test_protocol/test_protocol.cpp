// The serial link (lib/graspguide_link): CRC, COBS, the generated messages, the golden
// frames shared with the Python tests, and the parser's resynchronization.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <random>
#include <string>
#include <type_traits>
#include <vector>

#include "data/golden_frames.h"
#include "graspguide/config.h"
#include "graspguide/scene.h"
#include "graspguide/status.h"
#include "graspguide_device/application.h"
#include "graspguide_link/cobs.h"
#include "graspguide_link/core_status.h"
#include "graspguide_link/crc16.h"
#include "graspguide_link/frame.h"
#include "graspguide_link/messages.h"
#include "graspguide_link/parser.h"
#include "graspguide_link/writer.h"

namespace gl = graspguide::link;
namespace gg = graspguide;
using Bytes = std::vector<uint8_t>;

namespace {

constexpr uint32_t kSeed = 20240611;
constexpr int kRandomStreams = 100000;
constexpr int kRoundTripsPerMessage = 2000;

Bytes bytes_of(const char* s) { return Bytes(s, s + std::strlen(s)); }

// Bit-by-bit CRC-16/CCITT-FALSE, independent of the library's table.
uint16_t crc16_bitwise(const Bytes& data) {
  uint16_t crc = 0xFFFF;
  for (uint8_t b : data) {
    crc = static_cast<uint16_t>(crc ^ (b << 8));
    for (int i = 0; i < 8; ++i)
      crc = static_cast<uint16_t>((crc & 0x8000) ? (crc << 1) ^ 0x1021 : crc << 1);
  }
  return crc;
}

Bytes cobs_encode(const Bytes& in) {
  Bytes out(gl::cobs_max_encoded_size(in.size()));
  size_t n = 0;
  EXPECT_EQ(gl::cobs_encode(in.data(), in.size(), out.data(), out.size(), &n), gl::LinkStatus::kOk);
  out.resize(n);
  return out;
}

gl::LinkStatus cobs_decode(const Bytes& in, Bytes* out) {
  out->assign(in.size() + 1, 0xEE);
  size_t n = 0;
  const gl::LinkStatus s = gl::cobs_decode(in.data(), in.size(), out->data(), out->size(), &n);
  out->resize(s == gl::LinkStatus::kOk ? n : 0);
  return s;
}

template <class Msg>
Bytes wire_of(const Msg& msg, uint16_t seq) {
  Bytes out(gl::kMaxWireFrameSize);
  size_t n = 0;
  EXPECT_EQ(gl::write_frame(msg, seq, out.data(), out.size(), &n), gl::LinkStatus::kOk);
  out.resize(n);
  return out;
}

Bytes forge(uint8_t version, uint8_t msg_id, uint16_t seq, const Bytes& payload) {
  Bytes out(gl::kMaxWireFrameSize);
  size_t n = 0;
  gl::FrameHeader h;
  h.version = version;
  h.msg_id = msg_id;
  h.seq = seq;
  EXPECT_EQ(gl::encode_frame(h, payload.data(), payload.size(), out.data(), out.size(), &n),
            gl::LinkStatus::kOk);
  out.resize(n);
  return out;
}

// COBS + delimiter of arbitrary raw bytes (header, payload and CRC chosen by the test).
Bytes wire_of_raw(const Bytes& raw) {
  Bytes out = cobs_encode(raw);
  out.push_back(0);
  return out;
}

struct Received {
  gl::ParseEvent event;
  gl::FrameHeader header;
  Bytes payload;
};

std::vector<Received> feed(gl::FrameParser& p, const Bytes& stream) {
  std::vector<Received> out;
  for (uint8_t b : stream) {
    const gl::ParseEvent e = p.push(b);
    if (e == gl::ParseEvent::kNone) continue;
    Received r{e, {}, {}};
    if (gl::has_trusted_header(e)) {
      r.header = p.frame().header;
      r.payload.assign(p.frame().payload, p.frame().payload + p.frame().payload_size);
    }
    out.push_back(r);
  }
  return out;
}

std::vector<gl::ParseEvent> events(const std::vector<Received>& rs) {
  std::vector<gl::ParseEvent> out;
  for (const auto& r : rs) out.push_back(r.event);
  return out;
}

// Fills any generated message with random wire-valid values: floats get random bit
// patterns (NaNs included), since the wire must carry them bit-exactly.
struct Randomizer {
  std::mt19937& rng;

  void operator()(const char*, bool& v) { v = (rng() & 1) != 0; }
  void operator()(const char*, float& v) { v = gl::f32_from_bits(static_cast<uint32_t>(rng())); }
  template <class T, std::enable_if_t<std::is_integral_v<T>, int> = 0>
  void operator()(const char*, T& v) {
    v = static_cast<T>(rng());
  }
  template <class E, std::enable_if_t<std::is_enum_v<E>, int> = 0>
  void operator()(const char*, E& v) {
    v = gl::EnumInfo<E>::kValues[rng() % gl::EnumInfo<E>::kCount];
  }
  template <size_t N>
  void operator()(const char*, char (&s)[N]) {
    const size_t len = rng() % (N + 1);
    for (size_t i = 0; i < N; ++i) s[i] = i < len ? static_cast<char>(0x20 + rng() % 95) : '\0';
  }
  template <class T, size_t N>
  void operator()(const char* name, T (&a)[N]) {
    for (T& x : a) (*this)(name, x);
  }
};

template <class Msg>
Msg random_message(std::mt19937& rng) {
  Msg m;
  gl::for_each_field(m, Randomizer{rng});
  return m;
}

template <class Msg>
Bytes payload_of(const Msg& m) {
  Bytes out(Msg::kPayloadSize + 1);
  size_t n = 0;
  EXPECT_EQ(gl::pack(m, out.data(), out.size(), &n), gl::LinkStatus::kOk);
  out.resize(n);
  return out;
}

// A random valid message of a random type, as (msg_id, payload).
template <class... Ms>
void random_payload(gl::MessageList<Ms...>, std::mt19937& rng, uint8_t* id, Bytes* payload) {
  const size_t pick = rng() % sizeof...(Ms);
  size_t i = 0;
  ((i++ == pick ? (void)(*id = static_cast<uint8_t>(Ms::kId),
                         *payload = payload_of(random_message<Ms>(rng)))
                : (void)0),
   ...);
}

}  // namespace

// ---------------------------------------------------------------------------------------
// CRC
// ---------------------------------------------------------------------------------------

TEST(Crc16, KnownVectors) {
  const Bytes check = bytes_of("123456789");
  EXPECT_EQ(gl::crc16(check.data(), check.size()), 0x29B1);
  EXPECT_EQ(gl::crc16(nullptr, 0), 0xFFFF);
  const Bytes a = bytes_of("A");
  EXPECT_EQ(gl::crc16(a.data(), a.size()), 0xB915);
}

TEST(Crc16, TableMatchesBitwiseAndContinues) {
  std::mt19937 rng(kSeed);
  for (int t = 0; t < 200; ++t) {
    Bytes d(rng() % 300);
    for (auto& b : d) b = static_cast<uint8_t>(rng());
    const uint16_t whole = gl::crc16(d.data(), d.size());
    EXPECT_EQ(whole, crc16_bitwise(d));
    const size_t cut = d.empty() ? 0 : rng() % d.size();
    EXPECT_EQ(gl::crc16(d.data() + cut, d.size() - cut, gl::crc16(d.data(), cut)), whole);
  }
}

// ---------------------------------------------------------------------------------------
// COBS
// ---------------------------------------------------------------------------------------

TEST(Cobs, KnownEncodings) {
  EXPECT_EQ(cobs_encode({}), (Bytes{0x01}));
  EXPECT_EQ(cobs_encode({0x00}), (Bytes{0x01, 0x01}));
  EXPECT_EQ(cobs_encode({0x00, 0x00}), (Bytes{0x01, 0x01, 0x01}));
  EXPECT_EQ(cobs_encode({0x11, 0x22, 0x00, 0x33}), (Bytes{0x03, 0x11, 0x22, 0x02, 0x33}));
  EXPECT_EQ(cobs_encode({0x11, 0x22, 0x33, 0x44}), (Bytes{0x05, 0x11, 0x22, 0x33, 0x44}));
  EXPECT_EQ(cobs_encode({0x11, 0x00, 0x00, 0x00}), (Bytes{0x02, 0x11, 0x01, 0x01, 0x01}));
  Bytes run254(254), run255(255);
  for (size_t i = 0; i < 254; ++i) run254[i] = static_cast<uint8_t>(i + 1);
  for (size_t i = 0; i < 255; ++i) run255[i] = static_cast<uint8_t>(i % 255 + 1);
  Bytes e254{0xFF};  // no 0x01 after a full block that ends the input
  e254.insert(e254.end(), run254.begin(), run254.end());
  EXPECT_EQ(cobs_encode(run254), e254);
  Bytes e255 = e254;
  e255.push_back(0x02);
  e255.push_back(0xFF);
  EXPECT_EQ(cobs_encode(run255), e255);
}

TEST(Cobs, RoundTripsRunsAndZeros) {
  std::mt19937 rng(kSeed);
  const size_t runs[] = {0, 1, 2, 253, 254, 255, 256, 507, 508, 509, 600};
  std::vector<Bytes> cases;
  for (size_t n : runs) {
    Bytes all_zero(n, 0), run(n);
    for (auto& b : run) b = static_cast<uint8_t>(1 + rng() % 255);
    cases.push_back(all_zero);
    cases.push_back(run);
    Bytes framed = run;  // a run with zeros on both sides
    framed.insert(framed.begin(), 0);
    framed.push_back(0);
    cases.push_back(framed);
    Bytes two = run;  // two runs of n separated by one zero
    two.push_back(0);
    two.insert(two.end(), run.begin(), run.end());
    cases.push_back(two);
  }
  for (int t = 0; t < 2000; ++t) {
    Bytes d(rng() % 700);
    const uint32_t zero_per_mille = rng() % 1001;
    for (auto& b : d)
      b = (rng() % 1000 < zero_per_mille) ? 0 : static_cast<uint8_t>(1 + rng() % 255);
    cases.push_back(d);
  }
  for (const Bytes& d : cases) {
    const Bytes e = cobs_encode(d);
    EXPECT_LE(e.size(), gl::cobs_max_encoded_size(d.size()));
    EXPECT_EQ(std::count(e.begin(), e.end(), 0), 0);
    Bytes back;
    ASSERT_EQ(cobs_decode(e, &back), gl::LinkStatus::kOk) << d.size();
    EXPECT_EQ(back, d);
    // The stream decoder agrees with the one-shot decoder.
    gl::CobsStreamDecoder s;
    Bytes streamed(d.size() + 1);
    size_t n = 0;
    for (uint8_t b : e)
      ASSERT_EQ(s.push(b, streamed.data(), streamed.size(), &n), gl::LinkStatus::kOk);
    EXPECT_EQ(s.finish(), gl::LinkStatus::kOk);
    streamed.resize(n);
    EXPECT_EQ(streamed, d);
  }
}

TEST(Cobs, RejectsMalformedInputAndSmallBuffers) {
  Bytes out;
  EXPECT_EQ(cobs_decode({}, &out), gl::LinkStatus::kBadCobs);
  EXPECT_EQ(cobs_decode({0x03, 0x11}, &out), gl::LinkStatus::kBadCobs);        // block past end
  EXPECT_EQ(cobs_decode({0x03, 0x11, 0x00}, &out), gl::LinkStatus::kBadCobs);  // zero inside
  EXPECT_EQ(cobs_decode({0x00}, &out), gl::LinkStatus::kBadCobs);
  const Bytes data{0x11, 0x22, 0x00, 0x33};
  const Bytes enc = cobs_encode(data);
  for (size_t cap = 0; cap < enc.size(); ++cap) {
    uint8_t buf[8];
    size_t n = 0;
    EXPECT_EQ(gl::cobs_encode(data.data(), data.size(), buf, cap, &n),
              gl::LinkStatus::kBufferTooSmall);
  }
  for (size_t cap = 0; cap < data.size(); ++cap) {
    uint8_t buf[8];
    size_t n = 0;
    EXPECT_EQ(gl::cobs_decode(enc.data(), enc.size(), buf, cap, &n),
              gl::LinkStatus::kBufferTooSmall);
  }
}

// ---------------------------------------------------------------------------------------
// Schema: ids, sizes, and the values mirrored from the core
// ---------------------------------------------------------------------------------------

TEST(Schema, ErrorCodesMirrorTheCoreStatus) {
  size_t core_codes = 0;
  for (gl::ErrorCode c : gl::EnumInfo<gl::ErrorCode>::kValues) {
    const uint8_t v = static_cast<uint8_t>(c);
    if (v < gl::kLinkErrorBase) {
      ++core_codes;
      ASSERT_LT(v, gg::kStatusCount);
      EXPECT_STREQ(gl::enum_name(c), gg::status_name(static_cast<gg::Status>(v))) << int(v);
    }
  }
  EXPECT_EQ(core_codes, static_cast<size_t>(gg::kStatusCount));
  // core_status.h checks names and values at compile time; its conversion keeps the name.
  for (int v = 0; v < gg::kStatusCount; ++v) {
    const auto s = static_cast<gg::Status>(v);
    EXPECT_STREQ(gl::enum_name(gl::error_code_of(s)), gg::status_name(s)) << v;
  }
}

TEST(Schema, SceneEnumsMirrorTheCore) {
  auto lower = [](std::string s) {
    for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return s;
  };
  EXPECT_EQ(gl::EnumInfo<gl::ConstraintModel>::kCount, 3u);
  for (gl::ConstraintModel m : gl::EnumInfo<gl::ConstraintModel>::kValues)
    EXPECT_STREQ(gl::enum_name(m), gg::constraint_model_name(static_cast<gg::ConstraintModel>(m)));
  EXPECT_EQ(gl::EnumInfo<gl::Policy>::kCount, 2u);
  for (gl::Policy p : gl::EnumInfo<gl::Policy>::kValues)
    EXPECT_EQ(gl::enum_name(p), lower(gg::policy_name(static_cast<gg::Policy>(p))));
  EXPECT_EQ(gl::EnumInfo<gl::Mode>::kCount, 2u);
  for (gl::Mode m : gl::EnumInfo<gl::Mode>::kValues)
    EXPECT_EQ(gl::enum_name(m), lower(gg::mode_name(static_cast<gg::Mode>(m))));
  EXPECT_EQ(static_cast<int>(gl::kMaxContacts), gg::kMaxContacts);
}

TEST(Schema, DeviceStatesMirrorTheApplication) {
  namespace gd = graspguide::device;
  EXPECT_EQ(gl::EnumInfo<gl::DeviceState>::kCount, 4u);
  EXPECT_EQ(int(gl::DeviceState::kIdle), int(gd::DeviceState::kIdle));
  EXPECT_EQ(int(gl::DeviceState::kSceneSet), int(gd::DeviceState::kSceneSet));
  EXPECT_EQ(int(gl::DeviceState::kTrialRunning), int(gd::DeviceState::kTrialRunning));
  EXPECT_EQ(int(gl::DeviceState::kStopped), int(gd::DeviceState::kStopped));
  EXPECT_EQ(gl::kPoseWatchdogMs, uint32_t{GRASPGUIDE_STALE_TIMEOUT_MS});
}

template <class... Ms>
void check_ids(gl::MessageList<Ms...>) {
  const uint8_t ids[] = {static_cast<uint8_t>(Ms::kId)...};
  const size_t sizes[] = {Ms::kPayloadSize...};
  size_t largest = 0;
  for (size_t i = 0; i < sizeof...(Ms); ++i) {
    EXPECT_TRUE(gl::is_host_to_device_id(ids[i]) || gl::is_device_to_host_id(ids[i]))
        << int(ids[i]);
    for (size_t j = 0; j < i; ++j) EXPECT_NE(ids[i], ids[j]);
    size_t size = 0;
    EXPECT_TRUE(gl::payload_size_of(ids[i], &size));
    EXPECT_EQ(size, sizes[i]);
    largest = std::max(largest, sizes[i]);
  }
  EXPECT_EQ(largest, gl::kMaxPayloadSize);
  EXPECT_EQ(sizeof...(Ms), gl::kMessageCount);
}

TEST(Schema, IdsAreUniqueAndSizesConsistent) {
  check_ids(gl::AllMessages{});
  size_t size = 0;
  EXPECT_FALSE(gl::payload_size_of(0x00, &size));
  EXPECT_FALSE(gl::payload_size_of(0x3F, &size));
  EXPECT_STREQ(gl::message_name(0x03), "POSE");
  EXPECT_STREQ(gl::message_name(0x7F), "unknown");
  EXPECT_EQ(gl::kMaxWireFrameSize, 176u);  // docs/protocol.md: PLAN_BEGIN is the largest frame
  EXPECT_EQ(gl::kProtocolVersion, 4);
}

TEST(Schema, ParseEventsNameTheirErrorCodes) {
  for (size_t i = 0; i < gl::kParseEventCount; ++i) {
    const auto e = static_cast<gl::ParseEvent>(i);
    gl::ErrorCode code{};
    if (e == gl::ParseEvent::kNone || e == gl::ParseEvent::kFrame) {
      EXPECT_FALSE(gl::error_code_for(e, &code));
      continue;
    }
    ASSERT_TRUE(gl::error_code_for(e, &code));
    EXPECT_STREQ(gl::enum_name(code), gl::parse_event_name(e));
    EXPECT_GE(static_cast<uint8_t>(code), gl::kLinkErrorBase);
  }
}

// ---------------------------------------------------------------------------------------
// Messages
// ---------------------------------------------------------------------------------------

template <class Msg>
void round_trip_one_type(std::mt19937& rng) {
  for (int t = 0; t < kRoundTripsPerMessage; ++t) {
    const Msg m = random_message<Msg>(rng);
    const Bytes payload = payload_of(m);
    ASSERT_EQ(payload.size(), Msg::kPayloadSize);
    Msg back;
    ASSERT_EQ(gl::unpack(payload.data(), payload.size(), &back), gl::LinkStatus::kOk) << Msg::kName;
    EXPECT_TRUE(back == m) << Msg::kName;
    EXPECT_EQ(payload_of(back), payload);
    // Through a whole frame and the parser.
    const uint16_t seq = static_cast<uint16_t>(rng());
    const Bytes wire = wire_of(m, seq);
    EXPECT_LE(wire.size(), gl::kWireSizeBound<Msg>);
    gl::FrameParser p;
    const auto got = feed(p, wire);
    ASSERT_EQ(got.size(), 1u);
    ASSERT_EQ(got[0].event, gl::ParseEvent::kFrame) << Msg::kName;
    EXPECT_EQ(got[0].header.seq, seq);
    Msg parsed;
    ASSERT_EQ(gl::read_message(p.frame(), &parsed), gl::LinkStatus::kOk);
    EXPECT_TRUE(parsed == m);
  }
  // Wrong sizes are bad_length, whatever the bytes.
  Bytes big(Msg::kPayloadSize + 1, 0);
  Msg out;
  EXPECT_EQ(gl::unpack(big.data(), big.size(), &out), gl::LinkStatus::kBadLength);
  if (Msg::kPayloadSize > 0) {
    EXPECT_EQ(gl::unpack(big.data(), Msg::kPayloadSize - 1, &out), gl::LinkStatus::kBadLength);
    // pack needs the whole payload's room.
    size_t n = 0;
    EXPECT_EQ(gl::pack(Msg{}, big.data(), Msg::kPayloadSize - 1, &n),
              gl::LinkStatus::kBufferTooSmall);
  }
}

template <class... Ms>
void round_trip_all(gl::MessageList<Ms...>, std::mt19937& rng) {
  (round_trip_one_type<Ms>(rng), ...);
}

TEST(Messages, EveryMessageRoundTrips) {
  std::mt19937 rng(kSeed);
  round_trip_all(gl::AllMessages{}, rng);
}

TEST(Messages, DefaultsAreTheSchemaDefaults) {
  const gl::SetScene s;
  EXPECT_EQ(s.k, 3);
  EXPECT_EQ(s.y_axis[1], 1.0f);
  EXPECT_EQ(s.threshold_deg, 3.0f);
  EXPECT_EQ(s.hold_s, 0.5f);
  EXPECT_EQ(s.timeout_s, 90.0f);
  EXPECT_EQ(s.constraints, gl::ConstraintModel::kPaper);
  EXPECT_EQ(gl::Pose{}.quat_wxyz[0], 1.0f);
  EXPECT_EQ(gl::Hello{}.protocol_version, gl::kProtocolVersion);
}

TEST(Messages, RejectsValuesOutsideTheirSets) {
  gl::SetScene scene;
  Bytes p = payload_of(scene);
  uint8_t bad_field = 0xFF;
  gl::SetScene out;
  p[61] = 3;  // constraints: 0..2
  EXPECT_EQ(gl::unpack(p.data(), p.size(), &out, &bad_field), gl::LinkStatus::kBadEnumValue);
  EXPECT_EQ(bad_field, 3);
  p[61] = 0;
  p[63] = 2;  // mode: 0..1
  EXPECT_EQ(gl::unpack(p.data(), p.size(), &out, &bad_field), gl::LinkStatus::kBadEnumValue);
  EXPECT_EQ(bad_field, 5);

  Bytes pose = payload_of(gl::Pose{});
  pose[20] = 2;  // has_contacts is a bool
  gl::Pose pose_out;
  EXPECT_EQ(gl::unpack(pose.data(), pose.size(), &pose_out, &bad_field),
            gl::LinkStatus::kBadEnumValue);
  EXPECT_EQ(bad_field, 2);

  gl::HelloReply reply;
  std::memcpy(reply.board, "native", 6);
  Bytes r = payload_of(reply);
  gl::HelloReply reply_out;
  r[6 + 7] = 'x';  // a character after the NUL padding started
  EXPECT_EQ(gl::unpack(r.data(), r.size(), &reply_out, &bad_field), gl::LinkStatus::kBadEnumValue);
  EXPECT_EQ(bad_field, 3);
  r[6 + 7] = 0;
  r[6 + 1] = 0x07;  // not printable
  EXPECT_EQ(gl::unpack(r.data(), r.size(), &reply_out), gl::LinkStatus::kBadEnumValue);

  // We never write what no decoder accepts.
  scene.policy = static_cast<gl::Policy>(7);
  uint8_t buf[gl::kMaxWireFrameSize];
  size_t n = 0;
  EXPECT_EQ(gl::write_frame(scene, 1, buf, sizeof buf, &n), gl::LinkStatus::kBadEnumValue);
  reply.board[0] = '\n';
  EXPECT_EQ(gl::write_frame(reply, 1, buf, sizeof buf, &n), gl::LinkStatus::kBadEnumValue);
}

TEST(Messages, ReadMessageChecksTheType) {
  const Bytes wire = wire_of(gl::Ack{}, 1);
  gl::FrameParser p;
  ASSERT_EQ(feed(p, wire).size(), 1u);
  gl::Error e;
  EXPECT_EQ(gl::read_message(p.frame(), &e), gl::LinkStatus::kWrongMessage);
  gl::Ack a;
  EXPECT_EQ(gl::read_message(p.frame(), &a), gl::LinkStatus::kOk);
}

// ---------------------------------------------------------------------------------------
// Golden frames (same file as the Python tests: test/data/golden_frames.json)
// ---------------------------------------------------------------------------------------

TEST(GoldenFrames, DecodeAndReencodeToTheSameBytes) {
  size_t seen = 0;
  graspguide_link_test::for_each_golden_frame(
      [&](const char* name, uint16_t seq, const auto& message, const uint8_t* bytes, size_t size) {
        using Msg = std::decay_t<decltype(message)>;
        ++seen;
        const Bytes golden(bytes, bytes + size);
        EXPECT_EQ(wire_of(message, seq), golden) << name;
        gl::FrameParser p;
        const auto got = feed(p, golden);
        ASSERT_EQ(got.size(), 1u) << name;
        ASSERT_EQ(got[0].event, gl::ParseEvent::kFrame) << name;
        EXPECT_EQ(p.frame().header.seq, seq);
        EXPECT_EQ(p.frame().header.version, gl::kProtocolVersion);
        Msg decoded;
        ASSERT_EQ(gl::read_message(p.frame(), &decoded), gl::LinkStatus::kOk) << name;
        EXPECT_TRUE(decoded == message) << name;
        EXPECT_EQ(wire_of(decoded, seq), golden) << name;
      });
  EXPECT_EQ(seen, graspguide_link_test::kGoldenFrameCount);
}

TEST(GoldenFrames, CoverEveryMessage) {
  std::vector<uint8_t> ids;
  graspguide_link_test::for_each_golden_frame(
      [&](const char*, uint16_t, const auto& message, const uint8_t*, size_t) {
        ids.push_back(static_cast<uint8_t>(std::decay_t<decltype(message)>::kId));
      });
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  EXPECT_EQ(ids.size(), gl::kMessageCount);
}

std::vector<Bytes> golden_wires() {
  std::vector<Bytes> out;
  graspguide_link_test::for_each_golden_frame([&](const char*, uint16_t, const auto&,
                                                  const uint8_t* b,
                                                  size_t n) { out.emplace_back(b, b + n); });
  return out;
}

// ---------------------------------------------------------------------------------------
// Parser
// ---------------------------------------------------------------------------------------

TEST(Parser, FramesBackToBackAndIdleDelimiters) {
  const auto goldens = golden_wires();
  Bytes stream{0x00, 0x00};  // idle delimiters before, between and after are not frames
  for (int rep = 0; rep < 3; ++rep)
    for (const Bytes& g : goldens) {
      stream.insert(stream.end(), g.begin(), g.end());
      if (rep == 1) stream.push_back(0x00);
    }
  gl::FrameParser p;
  const auto got = feed(p, stream);
  ASSERT_EQ(got.size(), 3 * goldens.size());
  for (const auto& r : got) EXPECT_EQ(r.event, gl::ParseEvent::kFrame);
  EXPECT_EQ(p.good_frames(), 3 * goldens.size());
  EXPECT_EQ(p.bad_frames(), 0u);
}

TEST(Parser, ResyncsAfterGarbage) {
  const Bytes good = golden_wires()[1];
  std::mt19937 rng(kSeed);
  for (int t = 0; t < 200; ++t) {
    Bytes stream(1 + rng() % 300);
    for (auto& b : stream) b = static_cast<uint8_t>(rng());
    stream.push_back(0x00);  // the line's next delimiter ends the garbage
    stream.insert(stream.end(), good.begin(), good.end());
    gl::FrameParser p;
    const auto got = feed(p, stream);
    ASSERT_FALSE(got.empty());
    EXPECT_EQ(got.back().event, gl::ParseEvent::kFrame);
    EXPECT_EQ(p.good_frames(), 1u);
    EXPECT_EQ(p.bad_frames(), got.size() - 1);
  }
}

TEST(Parser, ResyncsAfterATruncatedFrame) {
  const auto goldens = golden_wires();
  const Bytes& a = goldens[1];  // SET_SCENE
  const Bytes& b = goldens[3];  // POSE
  for (size_t cut = 1; cut + 1 < a.size(); ++cut) {
    // The sender died mid-frame and resumed with a delimiter: only the cut frame is lost.
    Bytes stream(a.begin(), a.begin() + static_cast<long>(cut));
    stream.push_back(0x00);
    stream.insert(stream.end(), b.begin(), b.end());
    gl::FrameParser p;
    const auto got = feed(p, stream);
    ASSERT_EQ(got.size(), 2u) << cut;
    EXPECT_NE(got[0].event, gl::ParseEvent::kFrame) << cut;
    EXPECT_EQ(got[1].event, gl::ParseEvent::kFrame) << cut;
    // Without that delimiter the cut frame swallows the next one, but not the one after.
    Bytes merged(a.begin(), a.begin() + static_cast<long>(cut));
    merged.insert(merged.end(), b.begin(), b.end());
    merged.insert(merged.end(), b.begin(), b.end());
    gl::FrameParser q;
    const auto got2 = feed(q, merged);
    ASSERT_GE(got2.size(), 2u);
    EXPECT_NE(got2[0].event, gl::ParseEvent::kFrame);
    EXPECT_EQ(got2.back().event, gl::ParseEvent::kFrame);
    EXPECT_EQ(q.good_frames(), 1u);
  }
}

TEST(Parser, ResyncsAfterAnOversizedFrame) {
  const Bytes good = golden_wires()[0];
  for (size_t n : {gl::FrameParser::kBufferSize + 2, size_t{254}, size_t{255}, size_t{1000}}) {
    Bytes stream(n, 0x42);  // long non-zero noise: COBS code 0x42 blocks
    stream.push_back(0x00);
    stream.insert(stream.end(), good.begin(), good.end());
    gl::FrameParser p;
    const auto got = feed(p, stream);
    ASSERT_EQ(got.size(), 2u) << n;
    EXPECT_EQ(got[0].event, gl::ParseEvent::kTooLong);
    EXPECT_EQ(got[1].event, gl::ParseEvent::kFrame);
  }
  // A frame with a valid CRC but a payload beyond the largest message is too_long, too.
  Bytes raw{gl::kProtocolVersion, 0x02, 0x01, 0x00};
  raw.resize(gl::kHeaderSize + gl::kMaxPayloadSize + 1, 0x5A);
  const uint16_t crc = gl::crc16(raw.data(), raw.size());
  raw.push_back(static_cast<uint8_t>(crc));
  raw.push_back(static_cast<uint8_t>(crc >> 8));
  Bytes stream = wire_of_raw(raw);
  stream.insert(stream.end(), good.begin(), good.end());
  gl::FrameParser p;
  EXPECT_EQ(events(feed(p, stream)),
            (std::vector<gl::ParseEvent>{gl::ParseEvent::kTooLong, gl::ParseEvent::kFrame}));
  // The largest real frame fits exactly.
  gl::FrameParser q;
  EXPECT_EQ(events(feed(q, wire_of(gl::SetScene{}, 9))),
            (std::vector<gl::ParseEvent>{gl::ParseEvent::kFrame}));
}

TEST(Parser, EveryFlippedBitIsCaught) {
  const auto goldens = golden_wires();
  size_t flips = 0;
  for (const Bytes& g : goldens) {
    for (size_t i = 0; i + 1 < g.size(); ++i) {
      for (int bit = 0; bit < 8; ++bit) {
        Bytes stream = g;
        stream[i] = static_cast<uint8_t>(stream[i] ^ (1u << bit));
        stream.insert(stream.end(), g.begin(), g.end());
        gl::FrameParser p;
        const auto got = feed(p, stream);
        ++flips;
        // The damaged frame never parses (a flip to 0x00 splits it into two bad ones);
        // the clean copy after it always does.
        ASSERT_FALSE(got.empty());
        for (size_t k = 0; k + 1 < got.size(); ++k)
          EXPECT_NE(got[k].event, gl::ParseEvent::kFrame) << i << ":" << bit;
        EXPECT_EQ(got.back().event, gl::ParseEvent::kFrame);
        EXPECT_EQ(p.good_frames(), 1u);
      }
    }
  }
  EXPECT_GT(flips, 1000u);
}

TEST(Parser, HeaderErrorsKeepATrustedHeader) {
  const Bytes hello_payload{1};
  const Bytes good = golden_wires()[0];
  struct Case {
    Bytes wire;
    gl::ParseEvent expected;
    uint8_t msg_id;
  };
  const Case cases[] = {
      {forge(gl::kProtocolVersion + 1, 0x01, 77, hello_payload), gl::ParseEvent::kBadVersion, 0x01},
      {forge(gl::kProtocolVersion - 2, 0x01, 77, hello_payload), gl::ParseEvent::kBadVersion, 0x01},
      {forge(gl::kProtocolVersion, 0x3F, 77, hello_payload), gl::ParseEvent::kUnknownId, 0x3F},
      {forge(gl::kProtocolVersion, 0x00, 77, {}), gl::ParseEvent::kUnknownId, 0x00},
      {forge(gl::kProtocolVersion, 0xFF, 77, {}), gl::ParseEvent::kUnknownId, 0xFF},
      {forge(gl::kProtocolVersion, 0x01, 77, {}), gl::ParseEvent::kBadLength, 0x01},
      {forge(gl::kProtocolVersion, 0x01, 77, {1, 2}), gl::ParseEvent::kBadLength, 0x01},
      {forge(gl::kProtocolVersion, 0x05, 77, {0}), gl::ParseEvent::kBadLength, 0x05},
  };
  for (const Case& c : cases) {
    Bytes stream = c.wire;
    stream.insert(stream.end(), good.begin(), good.end());
    gl::FrameParser p;
    const auto got = feed(p, stream);
    ASSERT_EQ(got.size(), 2u);
    EXPECT_EQ(got[0].event, c.expected) << gl::parse_event_name(got[0].event);
    EXPECT_EQ(got[0].header.seq, 77);
    EXPECT_EQ(got[0].header.msg_id, c.msg_id);
    EXPECT_EQ(got[1].event, gl::ParseEvent::kFrame);
    EXPECT_EQ(p.event_count(c.expected), 1u);
  }
}

TEST(Parser, DeviceAcceptsOnlyHostToDeviceIds) {
  gl::FrameParser device(gl::Accept::kHostToDevice);
  gl::FrameParser host(gl::Accept::kDeviceToHost);
  const Bytes ack = wire_of(gl::Ack{}, 5);
  const Bytes pose = wire_of(gl::Pose{}, 6);
  EXPECT_EQ(events(feed(device, ack)), (std::vector<gl::ParseEvent>{gl::ParseEvent::kUnknownId}));
  EXPECT_EQ(events(feed(device, pose)), (std::vector<gl::ParseEvent>{gl::ParseEvent::kFrame}));
  EXPECT_EQ(events(feed(host, pose)), (std::vector<gl::ParseEvent>{gl::ParseEvent::kUnknownId}));
  EXPECT_EQ(events(feed(host, ack)), (std::vector<gl::ParseEvent>{gl::ParseEvent::kFrame}));
}

TEST(Parser, TooShortAndTruncatedCobs) {
  gl::FrameParser p;
  for (size_t n = 1; n < gl::kFrameOverhead; ++n) {
    const Bytes raw(n, 0x01);
    EXPECT_EQ(events(feed(p, wire_of_raw(raw))),
              (std::vector<gl::ParseEvent>{gl::ParseEvent::kTooShort}))
        << n;
  }
  // A code byte promising more data than arrives before the delimiter.
  EXPECT_EQ(events(feed(p, {0x09, 0x01, 0x02, 0x00})),
            (std::vector<gl::ParseEvent>{gl::ParseEvent::kBadCobs}));
  EXPECT_EQ(p.event_count(gl::ParseEvent::kTooShort), gl::kFrameOverhead - 1);
  EXPECT_EQ(p.event_count(gl::ParseEvent::kBadCobs), 1u);
  EXPECT_EQ(p.bad_frames(), gl::kFrameOverhead);
}

TEST(Parser, CountersAndDiscard) {
  const auto goldens = golden_wires();
  gl::FrameParser p;
  Bytes bad_crc = goldens[5];
  bad_crc[bad_crc.size() - 2] ^= 0x01;
  Bytes stream = goldens[0];
  stream.insert(stream.end(), bad_crc.begin(), bad_crc.end());
  stream.insert(stream.end(), goldens[2].begin(), goldens[2].end());
  feed(p, stream);
  EXPECT_EQ(p.good_frames(), 2u);
  EXPECT_EQ(p.bad_frames(), 1u);
  EXPECT_EQ(p.event_count(gl::ParseEvent::kBadCrc), 1u);
  // A partial frame dropped on purpose is not counted, and the next frame is clean.
  feed(p, Bytes(goldens[1].begin(), goldens[1].begin() + 10));
  p.discard_partial();
  feed(p, goldens[1]);
  EXPECT_EQ(p.good_frames(), 3u);
  EXPECT_EQ(p.bad_frames(), 1u);
  p.reset_counters();
  EXPECT_EQ(p.good_frames(), 0u);
  EXPECT_EQ(p.bad_frames(), 0u);
}

// 10^5 streams of random garbage with valid frames interleaved, through one parser: every
// valid frame comes out intact and in order, and nothing else comes out as a frame.
TEST(Parser, RecoversEveryFrameFromRandomStreams) {
  std::mt19937 rng(kSeed);
  gl::FrameParser p;
  struct Sent {
    uint8_t id;
    uint16_t seq;
    Bytes payload;
  };
  std::vector<Sent> sent;
  size_t next = 0;
  size_t bytes = 0;
  size_t mismatches = 0;
  auto push_all = [&](const Bytes& s) {
    bytes += s.size();
    for (uint8_t b : s) {
      if (p.push(b) != gl::ParseEvent::kFrame) continue;
      const gl::FrameView& f = p.frame();
      const Bytes payload(f.payload, f.payload + f.payload_size);
      if (next < sent.size() && sent[next].id == f.header.msg_id &&
          sent[next].seq == f.header.seq && sent[next].payload == payload)
        ++next;
      else
        ++mismatches;
    }
  };
  for (int s = 0; s < kRandomStreams; ++s) {
    Bytes garbage(rng() % 96);
    const uint32_t zero_per_mille = rng() % 4 == 0 ? 100 : 5;
    for (auto& b : garbage) b = (rng() % 1000 < zero_per_mille) ? 0 : static_cast<uint8_t>(rng());
    if (rng() % 4 == 0) {  // garbage that starts like a real frame: a truncated one
      uint8_t id = 0;
      Bytes payload;
      random_payload(gl::AllMessages{}, rng, &id, &payload);
      const Bytes w = forge(gl::kProtocolVersion, id, static_cast<uint16_t>(rng()), payload);
      garbage.insert(garbage.end(), w.begin(),
                     w.begin() + static_cast<long>(rng() % (w.size() - 1)));
    }
    garbage.push_back(0x00);
    push_all(garbage);
    const int frames = 1 + static_cast<int>(rng() % 3);
    for (int k = 0; k < frames; ++k) {
      Sent one{0, static_cast<uint16_t>(rng()), {}};
      random_payload(gl::AllMessages{}, rng, &one.id, &one.payload);
      sent.push_back(one);
      push_all(forge(gl::kProtocolVersion, one.id, one.seq, one.payload));
    }
  }
  EXPECT_EQ(next, sent.size());
  EXPECT_EQ(mismatches, 0u);
  EXPECT_EQ(p.good_frames(), sent.size());
  EXPECT_GT(bytes, 5000000u);
}

// ---------------------------------------------------------------------------------------
// Writer
// ---------------------------------------------------------------------------------------

TEST(Writer, BufferTooSmallAndPayloadTooLong) {
  const gl::PlanBegin scene;  // the largest message
  const Bytes wire = wire_of(scene, 3);
  EXPECT_EQ(wire.size(), gl::kMaxWireFrameSize);
  uint8_t buf[gl::kMaxWireFrameSize];
  for (size_t cap = 0; cap < wire.size(); ++cap) {
    size_t n = 0;
    EXPECT_EQ(gl::write_frame(scene, 3, buf, cap, &n), gl::LinkStatus::kBufferTooSmall) << cap;
  }
  const Bytes too_long(gl::kMaxPayloadSize + 1, 1);
  size_t n = 0;
  EXPECT_EQ(
      gl::encode_frame(gl::FrameHeader{}, too_long.data(), too_long.size(), buf, sizeof buf, &n),
      gl::LinkStatus::kTooLong);
}

TEST(Writer, SequenceCounterWraps) {
  gl::SequenceCounter c;
  EXPECT_EQ(c.next(), 0);
  for (int i = 1; i < 0xFFFF; ++i) c.next();
  EXPECT_EQ(c.next(), 0xFFFF);
  EXPECT_EQ(c.next(), 0);
}
