// The host-less results log: the store after the plan region, cut into fixed-size slots
// written once each, in order. A slot is erased (all 0xFF: the log ends at the first erased
// slot after the last written one), valid, or
// torn (a power cut stopped its write, or it is not ours): a torn slot is counted and
// skipped, never returned as a record, and never written again (flash cannot rewrite it
// without an erase, and nothing stored is overwritten silently).
//
// Slot layout (kLogSlotBytes, little-endian): magic "GGLR", plan_id, the record's fields,
// zero padding, CRC-32 of all of that, then one commit byte. The commit byte is the last
// byte written and is never 0xFF, so a write cut at any byte leaves it erased: a slot reads
// valid only when every byte of it was written, whatever values the CRC happens to have.
#pragma once

#include <cstdint>
#include <cstring>

#include "graspguide_device/nv_storage.h"
#include "graspguide_device/plan_store.h"
#include "graspguide_device/storage_crc.h"
#include "graspguide_device/study_plan.h"

namespace graspguide::device {

struct LogRecord {
  PlanTrial trial;
  bool success = false;
  float completion_s = 0, first_entry_s = -1, final_error_deg = 0;
  uint32_t samples = 0;
  uint16_t imu_faults = 0;
};

inline constexpr uint32_t kLogMagic = 0x524C4747u;  // "GGLR"; no byte is 0x00 or 0xFF
inline constexpr uint8_t kLogCommitByte = 0xA5;
inline constexpr uint32_t kLogRecordBytes = kPlanTrialBytes + 1 + 3 * 4 + 4 + 2;
// Multiples of 8 bytes: the program unit of many flash parts (STM32L4, nRF52 words).
inline constexpr uint32_t kLogSlotAlignBytes = 8;
inline constexpr uint32_t kLogSlotBytes =
    (4 + 4 + kLogRecordBytes + 4 + 1 + kLogSlotAlignBytes - 1) / kLogSlotAlignBytes *
    kLogSlotAlignBytes;
inline constexpr uint32_t kLogCrcOffset = kLogSlotBytes - 5;
inline constexpr uint32_t kLogCommitOffset = kLogSlotBytes - 1;
inline constexpr uint32_t kLogMaxSlots = 0xFFFFu;  // counted in uint16 on the wire
// Slots erased per write: each write is made durable, so few large writes are far quicker
// than one per slot, and 8 slots stay a small stack buffer.
inline constexpr uint32_t kLogEraseChunkSlots = 8;

class ResultsLog {
 public:
  explicit ResultsLog(NvStorage& store) : store_(store) {}

  // Scans the log: counts valid records and torn slots, and finds where the next append
  // goes. kTooSmall: the store has no room for the plan region and one slot.
  // kStorageFailed: a read failed (the log then reports nothing and refuses appends).
  StoreStatus mount() {
    reset_counts();
    mounted_ = false;
    const uint32_t size = store_.size_bytes();
    if (size < kPlanRegionBytes + kLogSlotBytes) return StoreStatus::kTooSmall;
    const uint32_t slots = (size - kPlanRegionBytes) / kLogSlotBytes;
    capacity_ = static_cast<uint16_t>(slots < kLogMaxSlots ? slots : kLogMaxSlots);
    // Every slot, not only up to the first erased one: an erase cut by a power loss may leave
    // erased slots in front of old records, and an append must never land in front of them.
    uint8_t slot[kLogSlotBytes];
    for (uint16_t i = 0; i < capacity_; ++i) {
      if (!store_.read(slot_offset(i), slot, kLogSlotBytes)) {
        reset_counts();
        return StoreStatus::kStorageFailed;
      }
      const Kind kind = classify(slot, nullptr, nullptr);
      if (kind == Kind::kErased) continue;
      count(kind, slot);
      next_slot_ = static_cast<uint16_t>(i + 1);
    }
    mounted_ = true;
    return StoreStatus::kOk;
  }

  uint16_t records() const { return records_; }
  uint16_t capacity() const { return capacity_; }
  uint16_t torn() const { return torn_; }
  bool full() const { return next_slot_ >= capacity_; }

  // Writes r into the next erased slot. kFull: no erased slot is left, nothing written.
  // kStorageFailed: not mounted, or the write failed; the slot is then classified as a
  // remount would see it (usually torn), so the counts stay what the store holds.
  StoreStatus append(const LogRecord& r, uint32_t plan_id) {
    if (!mounted_) return StoreStatus::kStorageFailed;
    if (full()) return StoreStatus::kFull;
    uint8_t slot[kLogSlotBytes];
    encode_slot(r, plan_id, slot);
    if (store_.write(slot_offset(next_slot_), slot, kLogSlotBytes)) {
      count(Kind::kValid, slot);
      ++next_slot_;
      return StoreStatus::kOk;
    }
    if (!store_.read(slot_offset(next_slot_), slot, kLogSlotBytes)) {
      // What the slot holds is unknown: never write it again, and call it torn.
      ++torn_;
      ++next_slot_;
      return StoreStatus::kStorageFailed;
    }
    const Kind kind = classify(slot, nullptr, nullptr);
    if (kind != Kind::kErased) {
      count(kind, slot);
      ++next_slot_;
    }
    return StoreStatus::kStorageFailed;
  }

  // The index-th valid record (0 = the oldest), skipping torn slots. kNoRecord: index >=
  // records(). kStorageFailed: a read failed, or the store no longer holds what mount saw.
  StoreStatus read(uint16_t index, LogRecord& r, uint32_t* plan_id = nullptr) {
    if (index >= records_) return StoreStatus::kNoRecord;
    // Downloads read in order: continue from the last record found instead of slot 0.
    uint16_t valid = 0;
    uint16_t s = 0;
    if (cache_valid_ && cache_index_ <= index) {
      valid = cache_index_;
      s = cache_slot_;
    }
    uint8_t slot[kLogSlotBytes];
    for (; s < next_slot_; ++s) {
      if (!store_.read(slot_offset(s), slot, kLogSlotBytes)) return StoreStatus::kStorageFailed;
      LogRecord rec;
      uint32_t id = 0;
      if (classify(slot, &rec, &id) != Kind::kValid) continue;
      if (valid == index) {
        cache_valid_ = true;
        cache_index_ = index;
        cache_slot_ = s;
        r = rec;
        if (plan_id) *plan_id = id;
        return StoreStatus::kOk;
      }
      ++valid;
    }
    cache_valid_ = false;
    return StoreStatus::kStorageFailed;
  }

  // Every slot back to 0xFF (the plan region is not touched), from the last slot to the
  // first, so a power cut part way usually leaves the oldest records and an erased tail
  // (mount() copes with any other pattern: appends always go after the last written slot).
  StoreStatus erase() {
    if (capacity_ == 0) {
      const StoreStatus m = mount();
      if (m != StoreStatus::kOk) return m;
    }
    uint8_t ff[kLogEraseChunkSlots * kLogSlotBytes];
    std::memset(ff, 0xFF, sizeof ff);
    for (uint32_t end = capacity_; end > 0;) {
      const uint32_t n = end < kLogEraseChunkSlots ? end : kLogEraseChunkSlots;
      end -= n;
      if (!store_.write(slot_offset(static_cast<uint16_t>(end)), ff, n * kLogSlotBytes)) {
        mount();
        return StoreStatus::kStorageFailed;
      }
    }
    return mount();
  }

  // True when a record was made under a plan other than plan_id: the device refuses to
  // store a new plan over a log that still holds another plan's results.
  bool holds_other_plan(uint32_t plan_id) const {
    if (records_ == 0) return false;
    return mixed_plans_ || first_plan_id_ != plan_id;
  }

 private:
  enum class Kind : uint8_t { kErased, kValid, kTorn };

  static uint32_t slot_offset(uint16_t s) { return kPlanRegionBytes + uint32_t(s) * kLogSlotBytes; }

  template <typename Sink>
  static bool encode_record(Sink& s, const LogRecord& r) {
    using namespace detail;
    return encode_trial(s, r.trial) && put_u8(s, r.success ? 1 : 0) && put_f32(s, r.completion_s) &&
           put_f32(s, r.first_entry_s) && put_f32(s, r.final_error_deg) && put_u32(s, r.samples) &&
           put_u16(s, r.imu_faults);
  }
  template <typename Source>
  static bool decode_record(Source& s, LogRecord& r) {
    using namespace detail;
    return decode_trial(s, r.trial) && get_bool(s, r.success) && get_f32(s, r.completion_s) &&
           get_f32(s, r.first_entry_s) && get_f32(s, r.final_error_deg) && get_u32(s, r.samples) &&
           get_u16(s, r.imu_faults);
  }

  static void encode_slot(const LogRecord& r, uint32_t plan_id, uint8_t (&slot)[kLogSlotBytes]) {
    using namespace detail;
    std::memset(slot, 0, kLogSlotBytes);
    BufferSink s(slot, kLogCrcOffset);
    put_u32(s, kLogMagic);
    put_u32(s, plan_id);
    encode_record(s, r);
    BufferSink tail(slot + kLogCrcOffset, 4);
    put_u32(tail, crc32(slot, kLogCrcOffset));
    slot[kLogCommitOffset] = kLogCommitByte;
  }

  static Kind classify(const uint8_t (&slot)[kLogSlotBytes], LogRecord* r, uint32_t* plan_id) {
    using namespace detail;
    bool erased = true;
    for (uint8_t b : slot) erased = erased && b == 0xFF;
    if (erased) return Kind::kErased;
    if (slot[kLogCommitOffset] != kLogCommitByte) return Kind::kTorn;
    BufferSource crc_src(slot + kLogCrcOffset, 4);
    uint32_t crc = 0;
    get_u32(crc_src, crc);
    if (crc != crc32(slot, kLogCrcOffset)) return Kind::kTorn;
    BufferSource s(slot, kLogCrcOffset);
    uint32_t magic = 0, id = 0;
    LogRecord rec;
    if (!get_u32(s, magic) || magic != kLogMagic || !get_u32(s, id) || !decode_record(s, rec))
      return Kind::kTorn;
    if (r) *r = rec;
    if (plan_id) *plan_id = id;
    return Kind::kValid;
  }

  void count(Kind kind, const uint8_t (&slot)[kLogSlotBytes]) {
    if (kind == Kind::kTorn) {
      ++torn_;
      return;
    }
    if (kind != Kind::kValid) return;
    uint32_t id = 0;
    detail::BufferSource s(slot + 4, 4);
    detail::get_u32(s, id);
    if (records_ == 0)
      first_plan_id_ = id;
    else if (id != first_plan_id_)
      mixed_plans_ = true;
    ++records_;
  }

  void reset_counts() {
    records_ = torn_ = next_slot_ = 0;
    first_plan_id_ = 0;
    mixed_plans_ = false;
    cache_valid_ = false;
  }

  NvStorage& store_;
  bool mounted_ = false;
  uint16_t capacity_ = 0, records_ = 0, torn_ = 0, next_slot_ = 0;
  uint32_t first_plan_id_ = 0;
  bool mixed_plans_ = false;
  bool cache_valid_ = false;
  uint16_t cache_index_ = 0, cache_slot_ = 0;
};

static_assert(kLogSlotBytes >= 4 + 4 + kLogRecordBytes + 4 + 1, "the slot holds the record");
static_assert(kLogMagic != 0xFFFFFFFFu, "a valid slot is never erased");

}  // namespace graspguide::device
