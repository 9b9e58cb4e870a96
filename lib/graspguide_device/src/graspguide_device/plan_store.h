// The study plan in non-volatile storage: a versioned region at offset 0 of the store,
// little-endian field by field (no struct padding or CPU byte order in it), CRC-32 checked.
// A region that is torn, foreign or of another layout version reads as "no plan", never as
// a wrong plan; a whole plan of an older layout loads as kOldLayout (never read with this
// layout's fields), so the device can say to store it again. Also the byte codec the results log
// shares (a record holds a plan trial).
#pragma once

#include <cstdint>
#include <cstring>

#include "graspguide_device/nv_storage.h"
#include "graspguide_device/storage_crc.h"
#include "graspguide_device/study_plan.h"

namespace graspguide::device {

// kNoRecord: ResultsLog::read past the last record. kBadPlan: save_plan refused a plan that
// fails check_header/check_trial (nothing written). kOldLayout: load_plan found a whole plan
// of an older layout version (stored by an older firmware): upload the plan again.
enum class StoreStatus : uint8_t {
  kOk = 0,
  kNoPlan,
  kFull,
  kStorageFailed,
  kTooSmall,
  kNoRecord,
  kBadPlan,
  kOldLayout,
};

inline constexpr uint32_t kPlanHeaderBytes = 168;   // PlanHeader's fields, packed
inline constexpr uint32_t kPlanTrialBytes = 35;     // PlanTrial's fields, packed
inline constexpr uint32_t kPlanPreambleBytes = 16;  // magic, version, reserved, length, CRC
// "GGPL" in the store's byte order. No byte of it is 0x00 or 0xFF, so a magic cut part way
// over an invalidated (zeroed) or erased one can never read as whole.
inline constexpr uint32_t kPlanMagic = 0x4C504747u;
// 2: the header ends with the participant's calibration (pwm_floor u8[4], gain f32[4]).
inline constexpr uint16_t kPlanLayoutVersion = 2;
// Rounded up to 4 KiB, the usual flash erase sector, so the log starts on a sector.
inline constexpr uint32_t kPlanSectorBytes = 4096;
inline constexpr uint32_t kPlanRegionBytes =
    (kPlanPreambleBytes + kPlanHeaderBytes + kPlanTrialBytes * kMaxPlanTrials + kPlanSectorBytes -
     1) /
    kPlanSectorBytes * kPlanSectorBytes;

namespace detail {

// Where encoded bytes go: a buffer, a CRC, or the store (put() returns false on a fault).
class BufferSink {
 public:
  BufferSink(uint8_t* buf, uint32_t capacity) : buf_(buf), capacity_(capacity) {}
  bool put(const uint8_t* d, uint32_t n) {
    if (n > capacity_ - pos_) return false;
    std::memcpy(buf_ + pos_, d, n);
    pos_ += n;
    return true;
  }
  uint32_t size() const { return pos_; }

 private:
  uint8_t* buf_;
  uint32_t capacity_, pos_ = 0;
};

class CrcSink {
 public:
  bool put(const uint8_t* d, uint32_t n) {
    crc_.update(d, n);
    size_ += n;
    return true;
  }
  uint32_t crc() const { return crc_.value(); }
  uint32_t size() const { return size_; }

 private:
  Crc32 crc_;
  uint32_t size_ = 0;
};

// Writes in chunks through a small buffer (no copy of the whole plan in RAM) and keeps the
// CRC of everything put.
class StoreSink {
 public:
  StoreSink(NvStorage& store, uint32_t offset) : store_(store), offset_(offset) {}
  bool put(const uint8_t* d, uint32_t n) {
    crc_.update(d, n);
    while (n > 0) {
      if (fill_ == kChunk && !flush()) return false;
      const uint32_t take = n < kChunk - fill_ ? n : kChunk - fill_;
      std::memcpy(buf_ + fill_, d, take);
      fill_ += take;
      d += take;
      n -= take;
    }
    return true;
  }
  bool flush() {
    if (fill_ == 0) return ok_;
    ok_ = ok_ && store_.write(offset_, buf_, fill_);
    offset_ += fill_;
    fill_ = 0;
    return ok_;
  }
  uint32_t crc() const { return crc_.value(); }

 private:
  static constexpr uint32_t kChunk = 64;
  NvStorage& store_;
  uint32_t offset_;
  uint8_t buf_[kChunk] = {};
  uint32_t fill_ = 0;
  bool ok_ = true;
  Crc32 crc_;
};

// Where decoded bytes come from; get() returns false past the end or on a read fault.
class BufferSource {
 public:
  BufferSource(const uint8_t* buf, uint32_t size) : buf_(buf), size_(size) {}
  bool get(uint8_t* d, uint32_t n) {
    if (n > size_ - pos_) return false;
    std::memcpy(d, buf_ + pos_, n);
    pos_ += n;
    return true;
  }

 private:
  const uint8_t* buf_;
  uint32_t size_, pos_ = 0;
};

class StoreSource {
 public:
  StoreSource(NvStorage& store, uint32_t offset, uint32_t length)
      : store_(store), offset_(offset), left_(length) {}
  bool get(uint8_t* d, uint32_t n) {
    if (n > left_ || !store_.read(offset_, d, n)) {
      read_failed_ = read_failed_ || n <= left_;
      return false;
    }
    crc_.update(d, n);
    offset_ += n;
    left_ -= n;
    return true;
  }
  uint32_t crc() const { return crc_.value(); }
  bool read_failed() const { return read_failed_; }

 private:
  NvStorage& store_;
  uint32_t offset_, left_;
  Crc32 crc_;
  bool read_failed_ = false;
};

template <typename Sink>
bool put_u8(Sink& s, uint8_t v) {
  return s.put(&v, 1);
}
template <typename Sink>
bool put_u16(Sink& s, uint16_t v) {
  const uint8_t b[2] = {static_cast<uint8_t>(v), static_cast<uint8_t>(v >> 8)};
  return s.put(b, 2);
}
template <typename Sink>
bool put_u32(Sink& s, uint32_t v) {
  const uint8_t b[4] = {static_cast<uint8_t>(v), static_cast<uint8_t>(v >> 8),
                        static_cast<uint8_t>(v >> 16), static_cast<uint8_t>(v >> 24)};
  return s.put(b, 4);
}
template <typename Sink>
bool put_f32(Sink& s, float v) {
  static_assert(sizeof(float) == 4, "IEEE-754 binary32 expected");
  uint32_t bits;
  std::memcpy(&bits, &v, 4);
  return put_u32(s, bits);
}
template <typename Sink>
bool put_f32s(Sink& s, const float* v, int n) {
  for (int i = 0; i < n; ++i)
    if (!put_f32(s, v[i])) return false;
  return true;
}

template <typename Source>
bool get_u8(Source& s, uint8_t& v) {
  return s.get(&v, 1);
}
// A stored bool is 0 or 1; anything else is not data this code wrote.
template <typename Source>
bool get_bool(Source& s, bool& v) {
  uint8_t b;
  if (!s.get(&b, 1) || b > 1) return false;
  v = b == 1;
  return true;
}
template <typename Source>
bool get_u16(Source& s, uint16_t& v) {
  uint8_t b[2];
  if (!s.get(b, 2)) return false;
  v = static_cast<uint16_t>(b[0] | (b[1] << 8));
  return true;
}
template <typename Source>
bool get_u32(Source& s, uint32_t& v) {
  uint8_t b[4];
  if (!s.get(b, 4)) return false;
  v = uint32_t(b[0]) | (uint32_t(b[1]) << 8) | (uint32_t(b[2]) << 16) | (uint32_t(b[3]) << 24);
  return true;
}
template <typename Source>
bool get_f32(Source& s, float& v) {
  uint32_t bits;
  if (!get_u32(s, bits)) return false;
  std::memcpy(&v, &bits, 4);
  return true;
}
template <typename Source>
bool get_f32s(Source& s, float* v, int n) {
  for (int i = 0; i < n; ++i)
    if (!get_f32(s, v[i])) return false;
  return true;
}

// The fields in the schema's order (PLAN_TRIAL without its position; PLAN_BEGIN).
template <typename Sink>
bool encode_trial(Sink& s, const PlanTrial& t) {
  return put_u16(s, t.trial_index) && put_u8(s, t.session) && put_u8(s, t.session_trial) &&
         put_u8(s, t.k) && put_u8(s, t.policy) && put_u8(s, t.mode) &&
         put_u8(s, t.familiarization ? 1 : 0) && put_u8(s, t.single_motor ? 1 : 0) &&
         put_u8(s, t.wrench_class) && put_u8(s, t.wrench_number) && put_f32s(s, t.wrench, 6);
}
template <typename Source>
bool decode_trial(Source& s, PlanTrial& t) {
  return get_u16(s, t.trial_index) && get_u8(s, t.session) && get_u8(s, t.session_trial) &&
         get_u8(s, t.k) && get_u8(s, t.policy) && get_u8(s, t.mode) &&
         get_bool(s, t.familiarization) && get_bool(s, t.single_motor) &&
         get_u8(s, t.wrench_class) && get_u8(s, t.wrench_number) && get_f32s(s, t.wrench, 6);
}

template <typename Sink>
bool encode_header(Sink& s, const PlanHeader& h) {
  return s.put(reinterpret_cast<const uint8_t*>(h.participant), kPlanParticipantBytes) &&
         put_u8(s, h.simulated ? 1 : 0) && s.put(h.config_hash, kPlanConfigHashBytes) &&
         put_u16(s, h.trial_count) && put_u8(s, h.constraints) && put_f32s(s, h.y_axis, 3) &&
         put_f32(s, h.threshold_deg) && put_f32(s, h.hold_s) && put_f32(s, h.timeout_s) &&
         put_f32(s, h.rest_s) && put_f32s(s, &h.hand_k3[0][0], 9) &&
         put_f32s(s, &h.hand_k4[0][0], 12) && put_f32s(s, h.imu_to_hand_wxyz, 4) &&
         s.put(h.pwm_floor, kMaxContacts) && put_f32s(s, h.gain, kMaxContacts);
}
template <typename Source>
bool decode_header(Source& s, PlanHeader& h) {
  return s.get(reinterpret_cast<uint8_t*>(h.participant), kPlanParticipantBytes) &&
         get_bool(s, h.simulated) && s.get(h.config_hash, kPlanConfigHashBytes) &&
         get_u16(s, h.trial_count) && get_u8(s, h.constraints) && get_f32s(s, h.y_axis, 3) &&
         get_f32(s, h.threshold_deg) && get_f32(s, h.hold_s) && get_f32(s, h.timeout_s) &&
         get_f32(s, h.rest_s) && get_f32s(s, &h.hand_k3[0][0], 9) &&
         get_f32s(s, &h.hand_k4[0][0], 12) && get_f32s(s, h.imu_to_hand_wxyz, 4) &&
         s.get(h.pwm_floor, kMaxContacts) && get_f32s(s, h.gain, kMaxContacts);
}

// The plan's stored bytes: the header, then header.trial_count trials (capped, so a bad
// count never reads past the array; check_header refuses it before anything is stored).
template <typename Sink>
bool encode_plan(Sink& s, const StudyPlan& p) {
  if (!encode_header(s, p.header)) return false;
  const uint16_t n = p.header.trial_count <= kMaxPlanTrials ? p.header.trial_count : 0;
  for (uint16_t i = 0; i < n; ++i)
    if (!encode_trial(s, p.trials[i])) return false;
  return true;
}

inline uint32_t plan_payload_bytes(uint16_t trial_count) {
  return kPlanHeaderBytes + kPlanTrialBytes * uint32_t(trial_count);
}

// In place: a StudyPlan temporary would cost its ~4.7 KB on a small stack again.
inline void clear_plan(StudyPlan& p) {
  p.header = PlanHeader{};
  for (PlanTrial& t : p.trials) t = PlanTrial{};
}

inline bool plan_ok(const StudyPlan& p) {
  uint8_t field = 0;
  if (check_header(p.header, &field) != PlanCheck::kOk) return false;
  for (uint16_t i = 0; i < p.header.trial_count; ++i)
    if (check_trial(p.trials[i], &field) != PlanCheck::kOk) return false;
  return true;
}

}  // namespace detail

// CRC-32 of the plan's stored bytes (header + its trials): identifies the plan, in the
// region's preamble and in every log record made under it.
inline uint32_t plan_id(const StudyPlan& plan) {
  detail::CrcSink s;
  detail::encode_plan(s, plan);
  return s.crc();
}

// Stores a checked plan (kBadPlan otherwise, nothing written). The previous plan's magic is
// zeroed first and the new magic written last, each its own write: a power cut at any byte
// leaves either the old plan untouched (cut before the first byte) or a region with no valid
// magic, which loads as kNoPlan. kStorageFailed: a write failed; the region then holds no
// plan unless nothing at all was written.
inline StoreStatus save_plan(NvStorage& store, const StudyPlan& plan) {
  using namespace detail;
  if (store.size_bytes() < kPlanRegionBytes) return StoreStatus::kTooSmall;
  if (!plan_ok(plan)) return StoreStatus::kBadPlan;
  const uint8_t zero[4] = {0, 0, 0, 0};
  if (!store.write(0, zero, 4)) return StoreStatus::kStorageFailed;
  StoreSink payload(store, kPlanPreambleBytes);
  if (!encode_plan(payload, plan) || !payload.flush()) return StoreStatus::kStorageFailed;
  uint8_t pre[kPlanPreambleBytes];
  BufferSink ps(pre, sizeof pre);
  put_u32(ps, kPlanMagic);
  put_u16(ps, kPlanLayoutVersion);
  put_u16(ps, 0);  // reserved
  put_u32(ps, plan_payload_bytes(plan.header.trial_count));
  put_u32(ps, payload.crc());
  if (!store.write(4, pre + 4, kPlanPreambleBytes - 4)) return StoreStatus::kStorageFailed;
  if (!store.write(0, pre, 4)) return StoreStatus::kStorageFailed;
  return StoreStatus::kOk;
}

// kOk with the stored plan; kOldLayout when it holds a plan of an older layout version;
// kNoPlan (plan reset to StudyPlan{}, as on any failure) when the region
// holds no complete, intact plan of this layout that passes the checks; kStorageFailed on a read
// fault; kTooSmall when the store cannot hold a plan region.
inline StoreStatus load_plan(NvStorage& store, StudyPlan& plan) {
  using namespace detail;
  clear_plan(plan);
  if (store.size_bytes() < kPlanRegionBytes) return StoreStatus::kTooSmall;
  uint8_t pre[kPlanPreambleBytes];
  if (!store.read(0, pre, sizeof pre)) return StoreStatus::kStorageFailed;
  BufferSource ps(pre, sizeof pre);
  uint32_t magic = 0, length = 0, crc = 0;
  uint16_t version = 0, reserved = 0;
  get_u32(ps, magic);
  get_u16(ps, version);
  get_u16(ps, reserved);
  get_u32(ps, length);
  get_u32(ps, crc);
  // The magic is written last, so an older version under it is a whole plan of that
  // layout: named, never decoded with this one's fields.
  if (magic == kPlanMagic && reserved == 0 && version >= 1 && version < kPlanLayoutVersion)
    return StoreStatus::kOldLayout;
  if (magic != kPlanMagic || version != kPlanLayoutVersion || reserved != 0 ||
      length < plan_payload_bytes(1) || length > plan_payload_bytes(kMaxPlanTrials))
    return StoreStatus::kNoPlan;
  StoreSource src(store, kPlanPreambleBytes, length);
  StudyPlan& p = plan;
  bool ok = decode_header(src, p.header) && p.header.trial_count >= 1 &&
            p.header.trial_count <= kMaxPlanTrials &&
            length == plan_payload_bytes(p.header.trial_count);
  for (uint16_t i = 0; ok && i < p.header.trial_count; ++i) ok = decode_trial(src, p.trials[i]);
  const bool read_failed = src.read_failed();
  // The CRC vouches for the bytes; the checks for what this firmware can run.
  if (!read_failed && ok && src.crc() == crc && plan_ok(p)) return StoreStatus::kOk;
  clear_plan(plan);  // never half a plan
  return read_failed ? StoreStatus::kStorageFailed : StoreStatus::kNoPlan;
}

}  // namespace graspguide::device
