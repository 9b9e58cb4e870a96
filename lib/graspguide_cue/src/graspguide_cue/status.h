// Every operation that can fail returns one of these; nothing reports failure as NaN.
#pragma once

#include <stdint.h>

namespace graspguide {

// One row per status: the enumerator, its stable snake_case name (logs, the JSON CLI and
// the protocol's ErrorCode, which graspguide_link/core_status.h checks against this list)
// and what is wrong and how to fix it, for people reading an error. The enum, the names
// and the messages are all expanded from this one list, so they cannot drift apart.
// clang-format off
#define GRASPGUIDE_STATUSES(X)                                                             \
  X(kOk, "ok",                                                                             \
    "ok")                                                                                  \
  X(kNonFiniteInput, "non_finite_input",                                                   \
    "an input is NaN or infinite; check the tracker data and the wrench")                  \
  X(kBadContactCount, "bad_contact_count",                                                 \
    "the scene needs 3 contacts (thumb, index, middle) or 4 (plus palm)")                  \
  X(kBadAxis, "bad_axis",                                                                  \
    "y_axis (default [0, 1, 0]) and a gravity direction must be finite, non-zero vectors") \
  X(kBadQuaternion, "bad_quaternion",                                                      \
    "orientation must be a finite, non-zero quaternion [w, x, y, z]")                      \
  X(kCoincidentContacts, "coincident_contacts",                                            \
    "two contacts (or a contact and the centroid) coincide; check the tracked positions")  \
  X(kImpreciseContacts, "imprecise_contacts",                                              \
    "the contacts are so far from the origin that this precision cannot resolve the hand;" \
    " send positions relative to a point near the hand (e.g. the palm)")                   \
  X(kZeroWrench, "zero_wrench",                                                            \
    "the wrench is zero; give the virtual object a non-zero force")                        \
  X(kZeroForce, "zero_force",                                                              \
    "the wrench has no force part, or one below 1e-6 of its moment, so there is no"        \
    " direction to align with gravity")                                                    \
  X(kRankDeficient, "rank_deficient",                                                      \
    "the contacts are (nearly) collinear, so the grasp cannot resist every wrench; spread" \
    " the contacts out")                                                                   \
  X(kQpInfeasible, "qp_infeasible",                                                        \
    "no contact forces satisfy the constraint model for this wrench")                      \
  X(kQpIterationLimit, "qp_iteration_limit",                                               \
    "the QP solver hit its iteration cap; raise max_iterations or report the scene")       \
  X(kNothingToDisplay, "nothing_to_display",                                               \
    "every motor level is zero for this policy; try policy F")                             \
  X(kTimeWentBackwards, "time_went_backwards",                                             \
    "timestamps must not decrease within a trial")                                         \
  X(kBadConfig, "bad_config",                                                              \
    "a trial parameter is out of range: 0 <= threshold_deg <= 180, 0 <= hold_s <= 600 and" \
    " hold_s <= timeout_s, 0 < timeout_s <= 1800 (max_iterations >= 1)")                \
  X(kImuStale, "imu_stale",                                                                \
    "no IMU sample for GRASPGUIDE_IMU_STALE_MS (or none yet); check the IMU's wiring, power" \
    " and I2C address")                                                                    \
  X(kImuStuck, "imu_stuck",                                                                \
    "the IMU repeated the same reading GRASPGUIDE_IMU_STUCK_SAMPLES times in a row; a live"  \
    " sensor's noise never does: power-cycle it and check the bus")                        \
  X(kImuOutOfRange, "imu_out_of_range",                                                    \
    "an IMU reading is NaN, infinite or beyond the part's configured full scale; check the" \
    " range the board sets against the limits it reports")                                 \
  X(kBadImuConfig, "bad_imu_config",                                                       \
    "an IMU health setting is out of range: 1 <= stale_ms <= 60000, stuck_samples >= 2,"   \
    " recovery_samples >= 1, full scales finite and > 0")
// clang-format on

enum class Status : uint8_t {
#define GRASPGUIDE_STATUS_ENUMERATOR(id, name, message) id,
  GRASPGUIDE_STATUSES(GRASPGUIDE_STATUS_ENUMERATOR)
#undef GRASPGUIDE_STATUS_ENUMERATOR
};

// Counted from the list itself, so a new row cannot be left out.
#define GRASPGUIDE_STATUS_ONE(id, name, message) +1
constexpr int kStatusCount = 0 GRASPGUIDE_STATUSES(GRASPGUIDE_STATUS_ONE);
#undef GRASPGUIDE_STATUS_ONE

// Tables, not switches: each is linked only where it is used (the messages stay out of
// images that only log names; on an AVR either table would sit in RAM). A class template's
// static members are C++14's way to define a table once in a header.
template <typename Unused = void>
struct StatusTables {
  static constexpr const char* kNames[kStatusCount] = {
#define GRASPGUIDE_STATUS_NAME(id, name, message) name,
      GRASPGUIDE_STATUSES(GRASPGUIDE_STATUS_NAME)
#undef GRASPGUIDE_STATUS_NAME
  };
  static constexpr const char* kMessages[kStatusCount] = {
#define GRASPGUIDE_STATUS_MESSAGE(id, name, message) message,
      GRASPGUIDE_STATUSES(GRASPGUIDE_STATUS_MESSAGE)
#undef GRASPGUIDE_STATUS_MESSAGE
  };
};
template <typename Unused>
constexpr const char* StatusTables<Unused>::kNames[kStatusCount];
template <typename Unused>
constexpr const char* StatusTables<Unused>::kMessages[kStatusCount];

constexpr const char* status_name(Status s) {
  return static_cast<int>(s) < kStatusCount ? StatusTables<>::kNames[static_cast<int>(s)]
                                            : "unknown";
}

constexpr const char* status_message(Status s) {
  return static_cast<int>(s) < kStatusCount ? StatusTables<>::kMessages[static_cast<int>(s)]
                                            : "unknown status";
}

}  // namespace graspguide
