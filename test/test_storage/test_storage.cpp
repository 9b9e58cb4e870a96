// The device's non-volatile storage: the stored study plan (plan_store.h), the append-only
// results log (results_log.h) and the simulator's file store. Power cuts are modelled by
// RamStorage's torn writes; every expectation follows from the storage contract (a torn or
// damaged structure is never read as data), not from a recorded run.
#include <gtest/gtest.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "../../src/boards/posix_sim/file_storage.h"
#include "graspguide_device/fake_storage.h"
#include "graspguide_device/plan_store.h"
#include "graspguide_device/results_log.h"
#include "graspguide_device/storage_crc.h"
#include "graspguide_device/study_plan.h"

namespace gd = graspguide::device;

namespace {

constexpr uint32_t kStore64KiB = 64 * 1024;
using Store64 = gd::RamStorage<kStore64KiB>;
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

// The paper's study shape: 4 familiarization trials, then 8 sessions (4 modalities x 2
// contact counts) of 12 wrenches: 100 trials.
gd::StudyPlan paper_plan() {
  gd::StudyPlan p;
  std::strncpy(p.header.participant, "U3", sizeof p.header.participant);
  p.header.simulated = true;
  for (uint8_t i = 0; i < 8; ++i) p.header.config_hash[i] = static_cast<uint8_t>(0x10 * i + 3);
  p.header.trial_count = 100;
  p.header.constraints = 0;
  const float k3[3][3] = {
      {0.045f, 0.045f, 0.035f}, {0.015f, 0.095f, 0.040f}, {-0.010f, 0.100f, 0.040f}};
  std::memcpy(p.header.hand_k3, k3, sizeof k3);
  std::memcpy(p.header.hand_k4, k3, sizeof k3);
  p.header.hand_k4[3][1] = 0.045f;
  p.header.imu_to_hand_wxyz[0] = 0.7071068f;
  p.header.imu_to_hand_wxyz[3] = 0.7071068f;
  for (uint16_t i = 0; i < 100; ++i) {
    gd::PlanTrial& t = p.trials[i];
    t.trial_index = static_cast<uint16_t>(i + 1);
    const bool fam = i < 4;
    t.familiarization = fam;
    t.session = fam ? 0 : static_cast<uint8_t>(1 + (i - 4) / 12);
    t.session_trial = fam ? static_cast<uint8_t>(i + 1) : static_cast<uint8_t>(1 + (i - 4) % 12);
    t.k = (t.session % 2) ? 3 : 4;
    t.policy = static_cast<uint8_t>((t.session / 2) % 2);
    t.mode = static_cast<uint8_t>((t.session / 4) % 2);
    t.wrench_number = fam ? static_cast<uint8_t>(i + 1) : static_cast<uint8_t>(1 + (i * 5) % 12);
    t.single_motor = !fam && t.wrench_number <= 5;
    t.wrench_class = fam ? 0 : (t.single_motor ? 1 : 2);
    for (int j = 0; j < 6; ++j) t.wrench[j] = 0.25f * float(j + 1) - 0.01f * float(i);
  }
  return p;
}

void expect_trial_eq(const gd::PlanTrial& a, const gd::PlanTrial& b) {
  EXPECT_EQ(a.trial_index, b.trial_index);
  EXPECT_EQ(a.session, b.session);
  EXPECT_EQ(a.session_trial, b.session_trial);
  EXPECT_EQ(a.k, b.k);
  EXPECT_EQ(a.policy, b.policy);
  EXPECT_EQ(a.mode, b.mode);
  EXPECT_EQ(a.familiarization, b.familiarization);
  EXPECT_EQ(a.single_motor, b.single_motor);
  EXPECT_EQ(a.wrench_class, b.wrench_class);
  EXPECT_EQ(a.wrench_number, b.wrench_number);
  for (int j = 0; j < 6; ++j) EXPECT_EQ(a.wrench[j], b.wrench[j]) << "wrench[" << j << "]";
}

bool trial_eq(const gd::PlanTrial& a, const gd::PlanTrial& b) {
  if (a.trial_index != b.trial_index || a.session != b.session ||
      a.session_trial != b.session_trial || a.k != b.k || a.policy != b.policy ||
      a.mode != b.mode || a.familiarization != b.familiarization ||
      a.single_motor != b.single_motor || a.wrench_class != b.wrench_class ||
      a.wrench_number != b.wrench_number)
    return false;
  for (int j = 0; j < 6; ++j)
    if (a.wrench[j] != b.wrench[j]) return false;
  return true;
}

void expect_plan_eq(const gd::StudyPlan& a, const gd::StudyPlan& b) {
  const gd::PlanHeader &x = a.header, &y = b.header;
  EXPECT_EQ(0, std::memcmp(x.participant, y.participant, sizeof x.participant));
  EXPECT_EQ(x.simulated, y.simulated);
  EXPECT_EQ(0, std::memcmp(x.config_hash, y.config_hash, sizeof x.config_hash));
  EXPECT_EQ(x.trial_count, y.trial_count);
  EXPECT_EQ(x.constraints, y.constraints);
  for (int i = 0; i < 3; ++i) EXPECT_EQ(x.y_axis[i], y.y_axis[i]);
  EXPECT_EQ(x.threshold_deg, y.threshold_deg);
  EXPECT_EQ(x.hold_s, y.hold_s);
  EXPECT_EQ(x.timeout_s, y.timeout_s);
  EXPECT_EQ(x.rest_s, y.rest_s);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_EQ(x.hand_k3[i][j], y.hand_k3[i][j]);
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_EQ(x.hand_k4[i][j], y.hand_k4[i][j]);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(x.imu_to_hand_wxyz[i], y.imu_to_hand_wxyz[i]);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(x.pwm_floor[i], y.pwm_floor[i]) << "pwm_floor " << i;
  for (int i = 0; i < 4; ++i) EXPECT_EQ(x.gain[i], y.gain[i]) << "gain " << i;
  for (uint16_t i = 0; i < x.trial_count && i < gd::kMaxPlanTrials; ++i) {
    SCOPED_TRACE("trial " + std::to_string(i));
    expect_trial_eq(a.trials[i], b.trials[i]);
  }
}

// A participant's calibration, exact in float32, away from the identity on every motor.
void calibrate(gd::PlanHeader& h) {
  const uint8_t floor[4] = {60, 75, 0, 254};
  const float gain[4] = {1.25f, 0.75f, 4.0f, 0.25f};
  std::memcpy(h.pwm_floor, floor, sizeof floor);
  std::memcpy(h.gain, gain, sizeof gain);
}

// The region an older firmware wrote: layout 1, whose header had no calibration (the
// first kPlanHeaderBytes - 20 bytes of this layout's), with its own length and CRC.
void write_layout1_plan(Store64& store, const gd::StudyPlan& p) {
  namespace sd = gd::detail;
  std::vector<uint8_t> payload(sd::plan_payload_bytes(p.header.trial_count));
  sd::BufferSink sink(payload.data(), uint32_t(payload.size()));
  ASSERT_TRUE(sd::encode_plan(sink, p));
  constexpr uint32_t kCalibrationBytes = 4 + 4 * 4;
  payload.erase(payload.begin() + (gd::kPlanHeaderBytes - kCalibrationBytes),
                payload.begin() + gd::kPlanHeaderBytes);
  uint8_t pre[gd::kPlanPreambleBytes];
  sd::BufferSink ps(pre, sizeof pre);
  sd::put_u32(ps, gd::kPlanMagic);
  sd::put_u16(ps, 1);
  sd::put_u16(ps, 0);
  sd::put_u32(ps, uint32_t(payload.size()));
  sd::put_u32(ps, gd::crc32(payload.data(), uint32_t(payload.size())));
  ASSERT_TRUE(store.write(gd::kPlanPreambleBytes, payload.data(), uint32_t(payload.size())));
  ASSERT_TRUE(store.write(0, pre, sizeof pre));
}

// Bytes save_plan writes in all: the zeroed magic, the payload, the preamble.
uint32_t plan_write_bytes(const gd::StudyPlan& p) {
  return 4 + gd::detail::plan_payload_bytes(p.header.trial_count) + gd::kPlanPreambleBytes;
}

gd::LogRecord make_record(uint16_t n) {
  gd::LogRecord r;
  r.trial.trial_index = static_cast<uint16_t>(n + 1);
  r.trial.session = static_cast<uint8_t>(n % 9);
  r.trial.session_trial = static_cast<uint8_t>(1 + n % 12);
  r.trial.k = n % 2 ? 4 : 3;
  r.trial.policy = n % 2;
  r.trial.mode = (n / 2) % 2;
  r.trial.familiarization = n < 4;
  r.trial.single_motor = n % 3 == 0;
  r.trial.wrench_class = static_cast<uint8_t>(n % 3);
  r.trial.wrench_number = static_cast<uint8_t>(n % 12 + 1);
  for (int j = 0; j < 6; ++j) r.trial.wrench[j] = float(n) * 0.5f - float(j);
  r.success = n % 4 != 1;
  r.completion_s = 3.25f + float(n);
  r.first_entry_s = n % 5 == 0 ? -1.0f : 1.5f + float(n);
  r.final_error_deg = 0.125f * float(n);
  r.samples = 1000u * n + 7u;
  r.imu_faults = static_cast<uint16_t>(n % 3);
  return r;
}

bool record_eq(const gd::LogRecord& a, const gd::LogRecord& b) {
  return trial_eq(a.trial, b.trial) && a.success == b.success && a.completion_s == b.completion_s &&
         a.first_entry_s == b.first_entry_s && a.final_error_deg == b.final_error_deg &&
         a.samples == b.samples && a.imu_faults == b.imu_faults;
}

}  // namespace

// ---------------------------------------------------------------------------------------
// CRC and layout
// ---------------------------------------------------------------------------------------

TEST(StorageCrc, MatchesTheStandardCheckValue) {
  // CRC-32/ISO-HDLC's published check value: the CRC of the ASCII digits 1..9.
  const char* digits = "123456789";
  EXPECT_EQ(0xCBF43926u, gd::crc32(reinterpret_cast<const uint8_t*>(digits), 9));
  gd::Crc32 split;  // fed in pieces, the same
  split.update(reinterpret_cast<const uint8_t*>(digits), 4);
  split.update(reinterpret_cast<const uint8_t*>(digits) + 4, 5);
  EXPECT_EQ(0xCBF43926u, split.value());
  EXPECT_EQ(0u, gd::crc32(nullptr, 0));
}

TEST(StorageLayout, SizesMatchTheEncodedFields) {
  gd::detail::CrcSink h, t;
  gd::detail::encode_header(h, gd::PlanHeader{});
  gd::detail::encode_trial(t, gd::PlanTrial{});
  EXPECT_EQ(gd::kPlanHeaderBytes, h.size());
  EXPECT_EQ(gd::kPlanTrialBytes, t.size());
  // The region holds the largest plan, and the log starts on a sector.
  EXPECT_GE(gd::kPlanRegionBytes,
            gd::kPlanPreambleBytes + gd::detail::plan_payload_bytes(gd::kMaxPlanTrials));
  EXPECT_EQ(0u, gd::kPlanRegionBytes % gd::kPlanSectorBytes);
  EXPECT_EQ(0u, gd::kLogSlotBytes % gd::kLogSlotAlignBytes);
  std::printf("storage layout: plan region %u B, log slot %u B, 64 KiB store holds %u records\n",
              unsigned(gd::kPlanRegionBytes), unsigned(gd::kLogSlotBytes),
              unsigned((kStore64KiB - gd::kPlanRegionBytes) / gd::kLogSlotBytes));
}

// ---------------------------------------------------------------------------------------
// Plan checks: one test per rule, each naming its field by the schema's order
// (PLAN_BEGIN: 0 participant ... 12 imu_to_hand_wxyz, 13 pwm_floor, 14 gain; PLAN_TRIAL: 0 position
// ... 11 wrench).
// ---------------------------------------------------------------------------------------

namespace {
uint8_t header_bad_field(const std::function<void(gd::PlanHeader&)>& change) {
  gd::PlanHeader h = paper_plan().header;
  change(h);
  uint8_t field = 0xEE;
  if (gd::check_header(h, &field) == gd::PlanCheck::kOk) return 0xFF;
  return field;
}
uint8_t trial_bad_field(const std::function<void(gd::PlanTrial&)>& change) {
  gd::PlanTrial t = paper_plan().trials[10];
  change(t);
  uint8_t field = 0xEE;
  if (gd::check_trial(t, &field) == gd::PlanCheck::kOk) return 0xFF;
  return field;
}
}  // namespace

TEST(PlanChecks, ThePaperPlanPasses) {
  const gd::StudyPlan p = paper_plan();
  uint8_t field = 0xEE;
  EXPECT_EQ(gd::PlanCheck::kOk, gd::check_header(p.header, &field));
  for (uint16_t i = 0; i < p.header.trial_count; ++i)
    EXPECT_EQ(gd::PlanCheck::kOk, gd::check_trial(p.trials[i], &field)) << i;
  EXPECT_EQ(gd::PlanCheck::kOk, gd::check_header(p.header, nullptr));  // no field wanted
}

TEST(PlanChecks, ParticipantMustBePrintableNonEmptyAndNulPadded) {
  EXPECT_EQ(0, header_bad_field([](gd::PlanHeader& h) { std::memset(h.participant, 0, 8); }));
  EXPECT_EQ(0, header_bad_field([](gd::PlanHeader& h) { h.participant[1] = '\n'; }));
  EXPECT_EQ(0, header_bad_field([](gd::PlanHeader& h) { h.participant[0] = char(0x80); }));
  EXPECT_EQ(0, header_bad_field([](gd::PlanHeader& h) { h.participant[5] = 'x'; }));  // after NUL
  EXPECT_EQ(0xFF,
            header_bad_field([](gd::PlanHeader& h) { std::memcpy(h.participant, "U1234567", 8); }));
}

TEST(PlanChecks, TrialCountIsOneToMax) {
  EXPECT_EQ(3, header_bad_field([](gd::PlanHeader& h) { h.trial_count = 0; }));
  EXPECT_EQ(3, header_bad_field([](gd::PlanHeader& h) { h.trial_count = gd::kMaxPlanTrials + 1; }));
  EXPECT_EQ(0xFF, header_bad_field([](gd::PlanHeader& h) { h.trial_count = gd::kMaxPlanTrials; }));
}

TEST(PlanChecks, ConstraintsAreAModel) {
  EXPECT_EQ(4, header_bad_field([](gd::PlanHeader& h) { h.constraints = 3; }));
  EXPECT_EQ(0xFF, header_bad_field([](gd::PlanHeader& h) { h.constraints = 2; }));
}

TEST(PlanChecks, YAxisFiniteAndNonZero) {
  EXPECT_EQ(5, header_bad_field([](gd::PlanHeader& h) { h.y_axis[1] = 0; }));
  EXPECT_EQ(5, header_bad_field([](gd::PlanHeader& h) { h.y_axis[2] = kNaN; }));
  EXPECT_EQ(5, header_bad_field([](gd::PlanHeader& h) { h.y_axis[0] = kInf; }));
}

TEST(PlanChecks, TrialTimingUsesTheTrialConfigRanges) {
  using graspguide::TrialField;
  const auto max_of = [](TrialField f) { return float(graspguide::trial_field_range(f).max); };
  EXPECT_EQ(6, header_bad_field([](gd::PlanHeader& h) { h.threshold_deg = -0.5f; }));
  EXPECT_EQ(6, header_bad_field([&](gd::PlanHeader& h) {
              h.threshold_deg = 2 * max_of(TrialField::kThresholdDeg);
            }));
  EXPECT_EQ(6, header_bad_field([](gd::PlanHeader& h) { h.threshold_deg = kNaN; }));
  EXPECT_EQ(7, header_bad_field([](gd::PlanHeader& h) { h.hold_s = -1; }));
  EXPECT_EQ(7, header_bad_field([](gd::PlanHeader& h) { h.hold_s = h.timeout_s + 1; }));
  EXPECT_EQ(8, header_bad_field([](gd::PlanHeader& h) { h.timeout_s = 0; }));  // exclusive min
  EXPECT_EQ(8, header_bad_field(
                   [&](gd::PlanHeader& h) { h.timeout_s = 2 * max_of(TrialField::kTimeoutS); }));
}

TEST(PlanChecks, RestIsZeroToMax) {
  EXPECT_EQ(9, header_bad_field([](gd::PlanHeader& h) { h.rest_s = -0.1f; }));
  EXPECT_EQ(9, header_bad_field([](gd::PlanHeader& h) { h.rest_s = gd::kPlanRestMaxS * 1.01f; }));
  EXPECT_EQ(9, header_bad_field([](gd::PlanHeader& h) { h.rest_s = kNaN; }));
  EXPECT_EQ(0xFF, header_bad_field([](gd::PlanHeader& h) { h.rest_s = gd::kPlanRestMaxS; }));
  EXPECT_EQ(0xFF, header_bad_field([](gd::PlanHeader& h) { h.rest_s = 0; }));
}

TEST(PlanChecks, HandsAreFiniteAndWithinReach) {
  EXPECT_EQ(
      10, header_bad_field([](gd::PlanHeader& h) { h.hand_k3[2][1] = gd::kPlanHandMaxM * 1.5f; }));
  EXPECT_EQ(10, header_bad_field([](gd::PlanHeader& h) { h.hand_k3[0][0] = kNaN; }));
  EXPECT_EQ(
      11, header_bad_field([](gd::PlanHeader& h) { h.hand_k4[3][2] = -gd::kPlanHandMaxM * 1.5f; }));
  EXPECT_EQ(11, header_bad_field([](gd::PlanHeader& h) { h.hand_k4[1][0] = kInf; }));
}

TEST(PlanChecks, ImuQuaternionFiniteWithAPlausibleNorm) {
  const auto set_norm = [](gd::PlanHeader& h, float n) {
    h.imu_to_hand_wxyz[0] = n;
    h.imu_to_hand_wxyz[1] = h.imu_to_hand_wxyz[2] = h.imu_to_hand_wxyz[3] = 0;
  };
  EXPECT_EQ(12,
            header_bad_field([&](gd::PlanHeader& h) { set_norm(h, gd::kPlanQuatNormMin * 0.9f); }));
  EXPECT_EQ(12,
            header_bad_field([&](gd::PlanHeader& h) { set_norm(h, gd::kPlanQuatNormMax * 1.1f); }));
  EXPECT_EQ(12, header_bad_field([](gd::PlanHeader& h) { h.imu_to_hand_wxyz[2] = kNaN; }));
  EXPECT_EQ(0xFF, header_bad_field([&](gd::PlanHeader& h) { set_norm(h, 1.2f); }));
}

TEST(PlanChecks, CalibrationFloorsAndGainsAreInTheirRanges) {
  EXPECT_EQ(13, header_bad_field([](gd::PlanHeader& h) { h.pwm_floor[2] = 255; }));
  EXPECT_EQ(14, header_bad_field([](gd::PlanHeader& h) {
              h.gain[1] = graspguide::kCalibrationGainMin * 0.99f;
            }));
  EXPECT_EQ(14, header_bad_field([](gd::PlanHeader& h) {
              h.gain[3] = graspguide::kCalibrationGainMax * 1.01f;
            }));
  EXPECT_EQ(14, header_bad_field([](gd::PlanHeader& h) { h.gain[0] = kNaN; }));
  EXPECT_EQ(14, header_bad_field([](gd::PlanHeader& h) { h.gain[0] = kInf; }));
  EXPECT_EQ(0xFF, header_bad_field([](gd::PlanHeader& h) { calibrate(h); }));  // the edges
  const gd::PlanHeader identity;
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(graspguide::kPwmMin, identity.pwm_floor[i]);
    EXPECT_EQ(1.0f, identity.gain[i]);
  }
}

TEST(PlanChecks, TheFirstBadHeaderFieldIsNamed) {
  EXPECT_EQ(3, header_bad_field([](gd::PlanHeader& h) {
              h.trial_count = 0;
              h.rest_s = -1;
              h.imu_to_hand_wxyz[0] = kNaN;
            }));
}

TEST(PlanChecks, TrialIndexAndSessionTrialStartAtOne) {
  EXPECT_EQ(1, trial_bad_field([](gd::PlanTrial& t) { t.trial_index = 0; }));
  EXPECT_EQ(3, trial_bad_field([](gd::PlanTrial& t) { t.session_trial = 0; }));
}

TEST(PlanChecks, ContactCountIsThreeOrFour) {
  EXPECT_EQ(4, trial_bad_field([](gd::PlanTrial& t) { t.k = 2; }));
  EXPECT_EQ(4, trial_bad_field([](gd::PlanTrial& t) { t.k = 5; }));
}

TEST(PlanChecks, PolicyModeAndWrenchClassAreTheirEnums) {
  EXPECT_EQ(5, trial_bad_field([](gd::PlanTrial& t) { t.policy = 2; }));
  EXPECT_EQ(6, trial_bad_field([](gd::PlanTrial& t) { t.mode = 2; }));
  EXPECT_EQ(9, trial_bad_field([](gd::PlanTrial& t) { t.wrench_class = 3; }));
}

TEST(PlanChecks, WrenchFiniteWithAForce) {
  EXPECT_EQ(11, trial_bad_field([](gd::PlanTrial& t) { t.wrench[4] = kNaN; }));
  EXPECT_EQ(11, trial_bad_field([](gd::PlanTrial& t) { t.wrench[0] = kInf; }));
  EXPECT_EQ(11,
            trial_bad_field([](gd::PlanTrial& t) { t.wrench[0] = t.wrench[1] = t.wrench[2] = 0; }));
  // A pure force is fine, a pure moment is not: the guidance follows the force direction.
  EXPECT_EQ(0xFF,
            trial_bad_field([](gd::PlanTrial& t) { t.wrench[3] = t.wrench[4] = t.wrench[5] = 0; }));
}

TEST(PlanChecks, TheFirstBadTrialFieldIsNamed) {
  EXPECT_EQ(4, trial_bad_field([](gd::PlanTrial& t) {
              t.k = 9;
              t.mode = 7;
              t.wrench[0] = kNaN;
            }));
}

// ---------------------------------------------------------------------------------------
// The stored plan
// ---------------------------------------------------------------------------------------

TEST(PlanStore, RoundTripsThePapersPlan) {
  auto store = std::make_unique<Store64>();
  const gd::StudyPlan plan = paper_plan();
  ASSERT_EQ(gd::StoreStatus::kOk, gd::save_plan(*store, plan));
  gd::StudyPlan back;
  ASSERT_EQ(gd::StoreStatus::kOk, gd::load_plan(*store, back));
  expect_plan_eq(plan, back);
  EXPECT_EQ(gd::plan_id(plan), gd::plan_id(back));
  // Only the plan region was written: the log's region stays erased.
  for (uint32_t i = gd::kPlanRegionBytes; i < kStore64KiB; ++i) ASSERT_EQ(0xFF, store->bytes()[i]);
}

TEST(PlanStore, ACalibrationIsStoredAndReloaded) {
  auto store = std::make_unique<Store64>();
  gd::StudyPlan plan = paper_plan();
  calibrate(plan.header);
  ASSERT_EQ(gd::StoreStatus::kOk, gd::save_plan(*store, plan));
  gd::StudyPlan back;
  ASSERT_EQ(gd::StoreStatus::kOk, gd::load_plan(*store, back));
  expect_plan_eq(plan, back);
  EXPECT_EQ(gd::plan_id(plan), gd::plan_id(back));
  EXPECT_NE(gd::plan_id(paper_plan()), gd::plan_id(back));  // another calibration, another plan
}

TEST(PlanStore, AnOldLayoutPlanIsRefusedNeverMisread) {
  auto store = std::make_unique<Store64>();
  write_layout1_plan(*store, paper_plan());
  gd::StudyPlan back = paper_plan();
  EXPECT_EQ(gd::StoreStatus::kOldLayout, gd::load_plan(*store, back));
  EXPECT_EQ(0, back.header.trial_count);  // nothing of it is read
  // This layout's plan under an older version number: the version decides, not the length.
  ASSERT_EQ(gd::StoreStatus::kOk, gd::save_plan(*store, paper_plan()));
  store->bytes()[4] = 1;
  EXPECT_EQ(gd::StoreStatus::kOldLayout, gd::load_plan(*store, back));
  // Storing the plan again replaces it.
  ASSERT_EQ(gd::StoreStatus::kOk, gd::save_plan(*store, paper_plan()));
  ASSERT_EQ(gd::StoreStatus::kOk, gd::load_plan(*store, back));
  expect_plan_eq(paper_plan(), back);
}

TEST(PlanStore, AnErasedStoreHoldsNoPlan) {
  auto store = std::make_unique<Store64>();
  gd::StudyPlan back = paper_plan();
  EXPECT_EQ(gd::StoreStatus::kNoPlan, gd::load_plan(*store, back));
  EXPECT_EQ(0, back.header.trial_count);  // nothing of the caller's old content survives
}

TEST(PlanStore, PlanIdIsStableAndChangesWithEveryField) {
  const gd::StudyPlan base = paper_plan();
  const uint32_t id = gd::plan_id(base);
  EXPECT_EQ(id, gd::plan_id(paper_plan()));
  std::vector<std::pair<std::string, std::function<void(gd::StudyPlan&)>>> changes = {
      {"participant", [](gd::StudyPlan& p) { p.header.participant[1] = '4'; }},
      {"simulated", [](gd::StudyPlan& p) { p.header.simulated = false; }},
      {"config_hash", [](gd::StudyPlan& p) { p.header.config_hash[7] ^= 1; }},
      {"trial_count", [](gd::StudyPlan& p) { p.header.trial_count = 99; }},
      {"constraints", [](gd::StudyPlan& p) { p.header.constraints = 1; }},
      {"y_axis", [](gd::StudyPlan& p) { p.header.y_axis[2] = 0.5f; }},
      {"threshold_deg", [](gd::StudyPlan& p) { p.header.threshold_deg = 2.5f; }},
      {"hold_s", [](gd::StudyPlan& p) { p.header.hold_s = 0.75f; }},
      {"timeout_s", [](gd::StudyPlan& p) { p.header.timeout_s = 60; }},
      {"rest_s", [](gd::StudyPlan& p) { p.header.rest_s = 3; }},
      {"hand_k3", [](gd::StudyPlan& p) { p.header.hand_k3[2][2] += 0.001f; }},
      {"hand_k4", [](gd::StudyPlan& p) { p.header.hand_k4[3][0] += 0.001f; }},
      {"imu_to_hand_wxyz", [](gd::StudyPlan& p) { p.header.imu_to_hand_wxyz[1] = 0.1f; }},
      {"pwm_floor", [](gd::StudyPlan& p) { p.header.pwm_floor[3] = 71; }},
      {"gain", [](gd::StudyPlan& p) { p.header.gain[0] = 1.0625f; }},
      {"trial_index", [](gd::StudyPlan& p) { p.trials[57].trial_index = 200; }},
      {"session", [](gd::StudyPlan& p) { p.trials[57].session += 1; }},
      {"session_trial", [](gd::StudyPlan& p) { p.trials[57].session_trial += 1; }},
      {"k", [](gd::StudyPlan& p) { p.trials[57].k = p.trials[57].k == 3 ? 4 : 3; }},
      {"policy", [](gd::StudyPlan& p) { p.trials[57].policy ^= 1; }},
      {"mode", [](gd::StudyPlan& p) { p.trials[57].mode ^= 1; }},
      {"familiarization", [](gd::StudyPlan& p) { p.trials[57].familiarization ^= true; }},
      {"single_motor", [](gd::StudyPlan& p) { p.trials[57].single_motor ^= true; }},
      {"wrench_class", [](gd::StudyPlan& p) { p.trials[57].wrench_class = 0; }},
      {"wrench_number", [](gd::StudyPlan& p) { p.trials[57].wrench_number += 1; }},
      {"wrench", [](gd::StudyPlan& p) { p.trials[57].wrench[5] += 0.001f; }},
      {"last trial", [](gd::StudyPlan& p) { p.trials[99].wrench[0] += 0.001f; }},
  };
  for (auto& c : changes) {
    gd::StudyPlan p = base;
    c.second(p);
    EXPECT_NE(id, gd::plan_id(p)) << c.first;
  }
  // Trials past trial_count are not part of the plan.
  gd::StudyPlan p = base;
  p.trials[100].k = 4;
  p.trials[127].wrench[0] = 5;
  EXPECT_EQ(id, gd::plan_id(p));
}

TEST(PlanStore, RefusesABadPlanAndWritesNothing) {
  auto store = std::make_unique<Store64>();
  gd::StudyPlan plan = paper_plan();
  plan.trials[42].k = 7;
  EXPECT_EQ(gd::StoreStatus::kBadPlan, gd::save_plan(*store, plan));
  EXPECT_EQ(0u, store->writes());
  plan = paper_plan();
  plan.header.trial_count = 0;
  EXPECT_EQ(gd::StoreStatus::kBadPlan, gd::save_plan(*store, plan));
  EXPECT_EQ(0u, store->writes());
}

TEST(PlanStore, AnySingleDamagedByteReadsAsNoPlan) {
  auto store = std::make_unique<Store64>();
  const gd::StudyPlan plan = paper_plan();
  ASSERT_EQ(gd::StoreStatus::kOk, gd::save_plan(*store, plan));
  const uint32_t stored =
      gd::kPlanPreambleBytes + gd::detail::plan_payload_bytes(plan.header.trial_count);
  gd::StudyPlan back;
  uint32_t misread = 0;
  for (const uint8_t flip : {uint8_t(0x01), uint8_t(0x80), uint8_t(0xFF)}) {
    for (uint32_t i = 0; i < stored; ++i) {
      store->bytes()[i] ^= flip;
      if (gd::load_plan(*store, back) != gd::StoreStatus::kNoPlan) ++misread;
      store->bytes()[i] ^= flip;
    }
  }
  EXPECT_EQ(0u, misread) << "of " << 3 * stored << " damaged regions";
  ASSERT_EQ(gd::StoreStatus::kOk, gd::load_plan(*store, back));  // undamaged again
  expect_plan_eq(plan, back);
}

TEST(PlanStore, ATornSaveNeverReadsAsAPlanItDidNotFinish) {
  const gd::StudyPlan old_plan = paper_plan();
  gd::StudyPlan new_plan = paper_plan();
  new_plan.header.participant[1] = '7';
  new_plan.header.trial_count = 60;
  calibrate(new_plan.header);
  const uint32_t total = plan_write_bytes(new_plan);
  auto erased = std::make_unique<Store64>();
  auto with_old = std::make_unique<Store64>();
  ASSERT_EQ(gd::StoreStatus::kOk, gd::save_plan(*with_old, old_plan));
  auto with_layout1 = std::make_unique<Store64>();  // stored by an older firmware
  write_layout1_plan(*with_layout1, old_plan);
  auto store = std::make_unique<Store64>();
  gd::StudyPlan back;
  uint32_t misread = 0;
  for (uint32_t m = 0; m <= total; ++m) {
    for (const Store64* start : {erased.get(), with_old.get(), with_layout1.get()}) {
      *store = *start;
      store->fail_writes_after_bytes(m);
      const gd::StoreStatus saved = gd::save_plan(*store, new_plan);
      store->restore_power();
      const gd::StoreStatus loaded = gd::load_plan(*store, back);
      if (m == total) {  // every byte written: the new plan
        EXPECT_EQ(gd::StoreStatus::kOk, saved);
        misread += loaded != gd::StoreStatus::kOk || gd::plan_id(back) != gd::plan_id(new_plan);
      } else if (m == 0 && start == with_old.get()) {  // nothing written: the old plan stands
        EXPECT_EQ(gd::StoreStatus::kStorageFailed, saved);
        misread += loaded != gd::StoreStatus::kOk || gd::plan_id(back) != gd::plan_id(old_plan);
      } else if (m == 0 && start == with_layout1.get()) {  // still the older firmware's plan
        EXPECT_EQ(gd::StoreStatus::kStorageFailed, saved);
        misread += loaded != gd::StoreStatus::kOldLayout;
      } else {
        EXPECT_EQ(gd::StoreStatus::kStorageFailed, saved) << m;
        misread += loaded != gd::StoreStatus::kNoPlan;
      }
    }
  }
  EXPECT_EQ(0u, misread);
  std::printf("torn-plan sweep: %u cut points x 3 starting states, %u misread\n",
              unsigned(total + 1), unsigned(misread));
}

TEST(PlanStore, ForeignBytesAreNoPlan) {
  auto store = std::make_unique<Store64>();
  for (uint32_t i = 0; i < gd::kPlanRegionBytes; ++i)
    store->bytes()[i] = static_cast<uint8_t>(i * 37u + 11u);
  gd::StudyPlan back;
  EXPECT_EQ(gd::StoreStatus::kNoPlan, gd::load_plan(*store, back));
}

TEST(PlanStore, AStoreTooSmallForThePlanRegion) {
  gd::RamStorage<gd::kPlanRegionBytes - 1> small;
  gd::StudyPlan back;
  EXPECT_EQ(gd::StoreStatus::kTooSmall, gd::save_plan(small, paper_plan()));
  EXPECT_EQ(gd::StoreStatus::kTooSmall, gd::load_plan(small, back));
}

TEST(PlanStore, AReadFaultIsNotNoPlan) {
  auto store = std::make_unique<Store64>();
  ASSERT_EQ(gd::StoreStatus::kOk, gd::save_plan(*store, paper_plan()));
  store->fail_reads();
  gd::StudyPlan back;
  EXPECT_EQ(gd::StoreStatus::kStorageFailed, gd::load_plan(*store, back));
  EXPECT_EQ(0, back.header.trial_count);
}

// ---------------------------------------------------------------------------------------
// The results log
// ---------------------------------------------------------------------------------------

TEST(ResultsLog, AppendsAndReadsBackInOrder) {
  auto store = std::make_unique<Store64>();
  ASSERT_EQ(gd::StoreStatus::kOk, gd::save_plan(*store, paper_plan()));
  const uint32_t id = gd::plan_id(paper_plan());
  gd::ResultsLog log(*store);
  ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
  EXPECT_EQ((kStore64KiB - gd::kPlanRegionBytes) / gd::kLogSlotBytes, log.capacity());
  EXPECT_EQ(0, log.records());
  constexpr uint16_t kN = 25;
  for (uint16_t n = 0; n < kN; ++n) ASSERT_EQ(gd::StoreStatus::kOk, log.append(make_record(n), id));
  EXPECT_EQ(kN, log.records());
  gd::ResultsLog again(*store);  // what a reboot sees
  ASSERT_EQ(gd::StoreStatus::kOk, again.mount());
  EXPECT_EQ(kN, again.records());
  EXPECT_EQ(0, again.torn());
  for (gd::ResultsLog* l : {&log, &again}) {
    // Out of order first (the read cache must not be trusted backwards), then in order.
    for (uint16_t n : {uint16_t(20), uint16_t(3), uint16_t(24), uint16_t(0)}) {
      gd::LogRecord r;
      uint32_t got_id = 0;
      ASSERT_EQ(gd::StoreStatus::kOk, l->read(n, r, &got_id));
      EXPECT_TRUE(record_eq(make_record(n), r)) << n;
      EXPECT_EQ(id, got_id);
    }
    for (uint16_t n = 0; n < kN; ++n) {
      gd::LogRecord r;
      ASSERT_EQ(gd::StoreStatus::kOk, l->read(n, r));
      EXPECT_TRUE(record_eq(make_record(n), r)) << n;
    }
    gd::LogRecord r;
    EXPECT_EQ(gd::StoreStatus::kNoRecord, l->read(kN, r));
    EXPECT_EQ(gd::StoreStatus::kNoRecord, l->read(0xFFFF, r));
  }
  gd::StudyPlan back;  // the plan is untouched by the log
  ASSERT_EQ(gd::StoreStatus::kOk, gd::load_plan(*store, back));
  EXPECT_EQ(id, gd::plan_id(back));
}

TEST(ResultsLog, KnowsWhichPlansItsRecordsBelongTo) {
  auto store = std::make_unique<Store64>();
  gd::ResultsLog log(*store);
  ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
  EXPECT_FALSE(log.holds_other_plan(0x1234));
  ASSERT_EQ(gd::StoreStatus::kOk, log.append(make_record(0), 0x1234));
  EXPECT_FALSE(log.holds_other_plan(0x1234));
  EXPECT_TRUE(log.holds_other_plan(0x9999));
  ASSERT_EQ(gd::StoreStatus::kOk, log.append(make_record(1), 0x9999));
  EXPECT_TRUE(log.holds_other_plan(0x1234));
  EXPECT_TRUE(log.holds_other_plan(0x9999));
  gd::ResultsLog again(*store);
  ASSERT_EQ(gd::StoreStatus::kOk, again.mount());
  EXPECT_TRUE(again.holds_other_plan(0x1234));
  EXPECT_TRUE(again.holds_other_plan(0x9999));
}

// The torn-record test: a power cut at every byte of a record's write.
TEST(ResultsLog, ATornRecordIsSkippedNeverMisread) {
  constexpr uint16_t kBefore = 3;
  constexpr uint32_t kId = 0xA11CE;
  auto start = std::make_unique<Store64>();
  {
    gd::ResultsLog log(*start);
    ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
    for (uint16_t n = 0; n < kBefore; ++n)
      ASSERT_EQ(gd::StoreStatus::kOk, log.append(make_record(n), kId));
  }
  const gd::LogRecord cut_record = make_record(kBefore);
  const gd::LogRecord next_record = make_record(kBefore + 1);
  auto store = std::make_unique<Store64>();
  uint32_t misread = 0, cuts = 0;
  const auto slot_at = [](uint16_t s) {
    return gd::kPlanRegionBytes + uint32_t(s) * gd::kLogSlotBytes;
  };
  for (uint32_t m = 0; m <= gd::kLogSlotBytes; ++m) {
    SCOPED_TRACE("cut after " + std::to_string(m) + " bytes");
    ++cuts;
    *store = *start;
    const bool complete = m == gd::kLogSlotBytes;
    const bool torn = m > 0 && !complete;
    {
      gd::ResultsLog log(*store);
      ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
      store->fail_writes_after_bytes(m);
      EXPECT_EQ(complete ? gd::StoreStatus::kOk : gd::StoreStatus::kStorageFailed,
                log.append(cut_record, kId));
      // The log that saw the failure counts what a remount would.
      EXPECT_EQ(kBefore + (complete ? 1 : 0), log.records());
      EXPECT_EQ(torn ? 1 : 0, log.torn());
    }
    store->restore_power();
    std::vector<uint8_t> cut_slot(store->bytes() + slot_at(kBefore),
                                  store->bytes() + slot_at(kBefore) + gd::kLogSlotBytes);
    gd::ResultsLog log(*store);  // the reboot
    ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
    const uint16_t expected = static_cast<uint16_t>(kBefore + (complete ? 1 : 0));
    EXPECT_EQ(expected, log.records());
    EXPECT_EQ(torn ? 1 : 0, log.torn());
    for (uint16_t n = 0; n < expected; ++n) {
      gd::LogRecord r;
      uint32_t id = 0;
      const bool same = log.read(n, r, &id) == gd::StoreStatus::kOk && id == kId &&
                        record_eq(n < kBefore ? make_record(n) : cut_record, r);
      misread += !same;
    }
    gd::LogRecord r;
    misread += log.read(expected, r) != gd::StoreStatus::kNoRecord;
    // The next record goes after the torn slot, which stays as it was, and reads back
    // intact. A cut before the first byte left the slot erased: the record goes there.
    ASSERT_EQ(gd::StoreStatus::kOk, log.append(next_record, kId));
    const uint16_t next_slot = static_cast<uint16_t>(kBefore + (m > 0 ? 1 : 0));
    if (m > 0)
      EXPECT_TRUE(std::equal(cut_slot.begin(), cut_slot.end(), store->bytes() + slot_at(kBefore)));
    else
      EXPECT_TRUE(
          std::all_of(cut_slot.begin(), cut_slot.end(), [](uint8_t b) { return b == 0xFF; }));
    EXPECT_NE(0xFF, store->bytes()[slot_at(next_slot)]);  // written there
    gd::ResultsLog after(*store);
    ASSERT_EQ(gd::StoreStatus::kOk, after.mount());
    EXPECT_EQ(expected + 1, after.records());
    EXPECT_EQ(torn ? 1 : 0, after.torn());
    misread += after.read(expected, r) != gd::StoreStatus::kOk || !record_eq(next_record, r);
  }
  EXPECT_EQ(0u, misread);
  std::printf("torn-record sweep: %u cut points (0..%u bytes of a %u-byte slot), %u misread\n",
              unsigned(cuts), unsigned(gd::kLogSlotBytes), unsigned(gd::kLogSlotBytes),
              unsigned(misread));
}

TEST(ResultsLog, ADamagedSlotIsTornNotARecord) {
  auto store = std::make_unique<Store64>();
  gd::ResultsLog log(*store);
  ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
  for (uint16_t n = 0; n < 3; ++n) ASSERT_EQ(gd::StoreStatus::kOk, log.append(make_record(n), 7));
  const uint32_t middle = gd::kPlanRegionBytes + gd::kLogSlotBytes;
  uint32_t misread = 0;
  for (uint32_t i = 0; i < gd::kLogSlotBytes; ++i) {
    store->bytes()[middle + i] ^= 0x10;
    gd::ResultsLog l(*store);
    ASSERT_EQ(gd::StoreStatus::kOk, l.mount());
    gd::LogRecord a, b;
    misread += l.records() != 2 || l.torn() != 1 || l.read(0, a) != gd::StoreStatus::kOk ||
               l.read(1, b) != gd::StoreStatus::kOk || !record_eq(make_record(0), a) ||
               !record_eq(make_record(2), b);
    store->bytes()[middle + i] ^= 0x10;
  }
  EXPECT_EQ(0u, misread);
}

TEST(ResultsLog, AFullStoreRefusesAndChangesNothing) {
  constexpr uint16_t kSlots = 4;
  gd::RamStorage<gd::kPlanRegionBytes + kSlots * gd::kLogSlotBytes + gd::kLogSlotBytes - 1> store;
  ASSERT_EQ(gd::StoreStatus::kOk, gd::save_plan(store, paper_plan()));
  gd::ResultsLog log(store);
  ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
  ASSERT_EQ(kSlots, log.capacity());  // the spare bytes make no slot
  for (uint16_t n = 0; n < kSlots; ++n) {
    EXPECT_FALSE(log.full());
    ASSERT_EQ(gd::StoreStatus::kOk, log.append(make_record(n), 1));
  }
  EXPECT_TRUE(log.full());
  const std::vector<uint8_t> before(store.bytes(), store.bytes() + store.size_bytes());
  const uint32_t writes = store.writes();
  EXPECT_EQ(gd::StoreStatus::kFull, log.append(make_record(9), 1));
  EXPECT_EQ(writes, store.writes());
  EXPECT_TRUE(std::equal(before.begin(), before.end(), store.bytes()));
  EXPECT_EQ(kSlots, log.records());
  gd::ResultsLog again(store);
  ASSERT_EQ(gd::StoreStatus::kOk, again.mount());
  EXPECT_TRUE(again.full());
  EXPECT_EQ(gd::StoreStatus::kFull, again.append(make_record(9), 1));
  EXPECT_TRUE(std::equal(before.begin(), before.end(), store.bytes()));
}

TEST(ResultsLog, EraseEmptiesTheLogAndKeepsThePlan) {
  auto store = std::make_unique<Store64>();
  const gd::StudyPlan plan = paper_plan();
  ASSERT_EQ(gd::StoreStatus::kOk, gd::save_plan(*store, plan));
  gd::ResultsLog log(*store);
  ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
  for (uint16_t n = 0; n < 10; ++n) ASSERT_EQ(gd::StoreStatus::kOk, log.append(make_record(n), 5));
  store->bytes()[gd::kPlanRegionBytes + 10 * gd::kLogSlotBytes + 3] = 0;  // a torn slot too
  ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
  ASSERT_EQ(1, log.torn());
  ASSERT_EQ(gd::StoreStatus::kOk, log.erase());
  EXPECT_EQ(0, log.records());
  EXPECT_EQ(0, log.torn());
  EXPECT_FALSE(log.holds_other_plan(99));
  for (uint32_t i = gd::kPlanRegionBytes; i < kStore64KiB; ++i)
    ASSERT_EQ(0xFF, store->bytes()[i]) << i;
  gd::StudyPlan back;
  ASSERT_EQ(gd::StoreStatus::kOk, gd::load_plan(*store, back));
  expect_plan_eq(plan, back);
  ASSERT_EQ(gd::StoreStatus::kOk, log.append(make_record(42), 5));
  gd::LogRecord r;
  ASSERT_EQ(gd::StoreStatus::kOk, log.read(0, r));
  EXPECT_TRUE(record_eq(make_record(42), r));
}

// An erase cut at any byte: what stays readable is old records in their order, and a new
// record lands after all of them.
TEST(ResultsLog, ATornEraseNeverPutsANewRecordBeforeAnOldOne) {
  constexpr uint16_t kSlots = 12, kOld = 10;
  using Small = gd::RamStorage<gd::kPlanRegionBytes + kSlots * gd::kLogSlotBytes>;
  Small start;
  {
    gd::ResultsLog log(start);
    ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
    for (uint16_t n = 0; n < kOld; ++n)
      ASSERT_EQ(gd::StoreStatus::kOk, log.append(make_record(n), 3));
  }
  uint32_t misread = 0;
  auto store = std::make_unique<Small>();
  for (uint32_t m = 0; m < kSlots * gd::kLogSlotBytes; ++m) {
    *store = start;
    gd::ResultsLog log(*store);
    ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
    store->fail_writes_after_bytes(m);
    EXPECT_EQ(gd::StoreStatus::kStorageFailed, log.erase());
    store->restore_power();
    gd::ResultsLog after(*store);
    ASSERT_EQ(gd::StoreStatus::kOk, after.mount());
    const uint16_t left = after.records();
    int last = -1;  // the old records left keep their order
    for (uint16_t i = 0; i < left; ++i) {
      gd::LogRecord r;
      if (after.read(i, r) != gd::StoreStatus::kOk) {
        ++misread;
        continue;
      }
      int which = -1;
      for (uint16_t n = 0; n < kOld; ++n)
        if (record_eq(make_record(n), r)) which = n;
      misread += which <= last;
      last = which;
    }
    ASSERT_FALSE(after.full());  // kOld < kSlots: the erase's first write frees the last slot
    misread += after.append(make_record(77), 3) != gd::StoreStatus::kOk;
    gd::ResultsLog rebooted(*store);  // the new record is the last one, after a reboot too
    ASSERT_EQ(gd::StoreStatus::kOk, rebooted.mount());
    gd::LogRecord r;
    misread += rebooted.records() != left + 1 || rebooted.read(left, r) != gd::StoreStatus::kOk ||
               !record_eq(make_record(77), r);
  }
  EXPECT_EQ(0u, misread);
}

TEST(ResultsLog, AReadFaultIsReported) {
  auto store = std::make_unique<Store64>();
  gd::ResultsLog log(*store);
  ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
  ASSERT_EQ(gd::StoreStatus::kOk, log.append(make_record(0), 1));
  ASSERT_EQ(gd::StoreStatus::kOk, log.append(make_record(1), 1));
  store->fail_reads();
  gd::LogRecord r;
  EXPECT_EQ(gd::StoreStatus::kStorageFailed, log.read(1, r));
  gd::ResultsLog again(*store);
  EXPECT_EQ(gd::StoreStatus::kStorageFailed, again.mount());
  EXPECT_EQ(0, again.records());
  // An unmounted log refuses to append: it does not know where the end is.
  store->fail_reads(false);
  EXPECT_EQ(gd::StoreStatus::kStorageFailed, again.append(make_record(2), 1));
  EXPECT_EQ(gd::StoreStatus::kOk, again.mount());
  EXPECT_EQ(2, again.records());
}

TEST(ResultsLog, AStoreTooSmallForOneSlot) {
  gd::RamStorage<gd::kPlanRegionBytes + gd::kLogSlotBytes - 1> small;
  gd::ResultsLog log(small);
  EXPECT_EQ(gd::StoreStatus::kTooSmall, log.mount());
  EXPECT_EQ(0, log.capacity());
  EXPECT_TRUE(log.full());
  EXPECT_EQ(gd::StoreStatus::kStorageFailed, log.append(make_record(0), 1));
  gd::RamStorage<gd::kPlanRegionBytes + gd::kLogSlotBytes> one;
  gd::ResultsLog log1(one);
  EXPECT_EQ(gd::StoreStatus::kOk, log1.mount());
  EXPECT_EQ(1, log1.capacity());
}

// ---------------------------------------------------------------------------------------
// The simulator's file store
// ---------------------------------------------------------------------------------------

namespace {
struct TempDir {
  std::string path;
  TempDir() {
    char tmpl[] = "/tmp/test_storage.XXXXXX";
    const char* p = mkdtemp(tmpl);
    path = p ? p : "";
  }
  ~TempDir() {
    if (!path.empty()) std::system(("rm -rf '" + path + "'").c_str());
  }
  std::string file(const char* name) const { return path + "/" + name; }
};

off_t file_size(const std::string& path) {
  struct stat st;
  return ::stat(path.c_str(), &st) == 0 ? st.st_size : -1;
}
}  // namespace

TEST(FileStorage, CreatesAnErasedFileOfTheStoresSize) {
  TempDir dir;
  ASSERT_FALSE(dir.path.empty());
  const std::string path = dir.file("store.bin");
  graspguide::sim::FileStorage f;
  std::string error;
  ASSERT_TRUE(f.open(path.c_str(), kStore64KiB, &error)) << error;
  EXPECT_EQ(kStore64KiB, f.size_bytes());
  EXPECT_EQ(off_t(kStore64KiB), file_size(path));
  std::vector<uint8_t> all(kStore64KiB);
  ASSERT_TRUE(f.read(0, all.data(), kStore64KiB));
  for (uint8_t b : all) ASSERT_EQ(0xFF, b);
  uint8_t one = 0;
  EXPECT_FALSE(f.read(kStore64KiB, &one, 1));  // past the end
  EXPECT_FALSE(f.write(kStore64KiB - 1, all.data(), 2));
  EXPECT_EQ(off_t(kStore64KiB), file_size(path));
}

TEST(FileStorage, ExtendsAShorterFileWithErasedBytes) {
  TempDir dir;
  const std::string path = dir.file("short.bin");
  {
    FILE* fp = std::fopen(path.c_str(), "wb");
    ASSERT_NE(nullptr, fp);
    const std::vector<uint8_t> head(100, 0x11);
    std::fwrite(head.data(), 1, head.size(), fp);
    std::fclose(fp);
  }
  graspguide::sim::FileStorage f;
  std::string error;
  ASSERT_TRUE(f.open(path.c_str(), 4096, &error)) << error;
  std::vector<uint8_t> all(4096);
  ASSERT_TRUE(f.read(0, all.data(), 4096));
  for (size_t i = 0; i < all.size(); ++i) ASSERT_EQ(i < 100 ? 0x11 : 0xFF, all[i]) << i;
  EXPECT_EQ(off_t(4096), file_size(path));
}

TEST(FileStorage, RefusesALongerFileAndASecondUser) {
  TempDir dir;
  const std::string path = dir.file("store.bin");
  std::string error;
  {
    graspguide::sim::FileStorage f;
    ASSERT_TRUE(f.open(path.c_str(), 8192, &error)) << error;
    graspguide::sim::FileStorage second;
    EXPECT_FALSE(second.open(path.c_str(), 8192, &error));
    EXPECT_NE(std::string::npos, error.find("in use")) << error;
  }
  graspguide::sim::FileStorage f;
  error.clear();
  EXPECT_FALSE(f.open(path.c_str(), 4096, &error));
  EXPECT_FALSE(f.is_open());
  EXPECT_NE(std::string::npos, error.find("8192")) << error;
  EXPECT_NE(std::string::npos, error.find("4096")) << error;
  EXPECT_EQ(off_t(8192), file_size(path));  // left as it was
  EXPECT_FALSE(f.open(dir.file("no/such/dir").c_str(), 4096, &error));
  EXPECT_NE(std::string::npos, error.find("cannot open")) << error;
}

TEST(FileStorage, ThePlanAndTheLogSurviveAReopen) {
  TempDir dir;
  const std::string path = dir.file("store.bin");
  const gd::StudyPlan plan = paper_plan();
  std::string error;
  {
    graspguide::sim::FileStorage f;
    ASSERT_TRUE(f.open(path.c_str(), kStore64KiB, &error)) << error;
    ASSERT_EQ(gd::StoreStatus::kOk, gd::save_plan(f, plan));
    gd::ResultsLog log(f);
    ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
    for (uint16_t n = 0; n < 5; ++n)
      ASSERT_EQ(gd::StoreStatus::kOk, log.append(make_record(n), gd::plan_id(plan)));
  }
  graspguide::sim::FileStorage f;
  ASSERT_TRUE(f.open(path.c_str(), kStore64KiB, &error)) << error;
  gd::StudyPlan back;
  ASSERT_EQ(gd::StoreStatus::kOk, gd::load_plan(f, back));
  expect_plan_eq(plan, back);
  gd::ResultsLog log(f);
  ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
  ASSERT_EQ(5, log.records());
  for (uint16_t n = 0; n < 5; ++n) {
    gd::LogRecord r;
    uint32_t id = 0;
    ASSERT_EQ(gd::StoreStatus::kOk, log.read(n, r, &id));
    EXPECT_TRUE(record_eq(make_record(n), r));
    EXPECT_EQ(gd::plan_id(plan), id);
  }
}

// The simulated device killed right after a record's append returned: the record is there.
TEST(FileStorage, ARecordSurvivesASigkillRightAfterItsWrite) {
  TempDir dir;
  const std::string path = dir.file("store.bin");
  constexpr uint16_t kRecords = 3;
  std::fflush(nullptr);
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    graspguide::sim::FileStorage f;
    std::string error;
    if (!f.open(path.c_str(), kStore64KiB, &error)) _exit(10);
    gd::ResultsLog log(f);
    if (log.mount() != gd::StoreStatus::kOk) _exit(11);
    for (uint16_t n = 0; n < kRecords; ++n)
      if (log.append(make_record(n), 0xBEEF) != gd::StoreStatus::kOk) _exit(12);
    kill(getpid(), SIGKILL);  // no close, no exit handlers: as a kill -9 mid-study
    _exit(13);
  }
  int status = 0;
  ASSERT_EQ(child, waitpid(child, &status, 0));
  ASSERT_TRUE(WIFSIGNALED(status)) << "child exited with " << WEXITSTATUS(status);
  ASSERT_EQ(SIGKILL, WTERMSIG(status));
  graspguide::sim::FileStorage f;
  std::string error;
  ASSERT_TRUE(f.open(path.c_str(), kStore64KiB, &error)) << error;  // the lock died with it
  gd::ResultsLog log(f);
  ASSERT_EQ(gd::StoreStatus::kOk, log.mount());
  EXPECT_EQ(kRecords, log.records());
  EXPECT_EQ(0, log.torn());
  for (uint16_t n = 0; n < kRecords; ++n) {
    gd::LogRecord r;
    uint32_t id = 0;
    ASSERT_EQ(gd::StoreStatus::kOk, log.read(n, r, &id));
    EXPECT_TRUE(record_eq(make_record(n), r)) << n;
    EXPECT_EQ(0xBEEFu, id);
  }
}
