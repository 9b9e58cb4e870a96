// Every operation that can fail returns one of these; nothing reports failure as NaN.
#pragma once

#include <cstdint>

namespace graspguide {

enum class Status : uint8_t {
  kOk = 0,
  kNonFiniteInput,
  kBadContactCount,
  kBadAxis,
  kBadQuaternion,
  kCoincidentContacts,
  kImpreciseContacts,
  kZeroWrench,
  kZeroForce,
  kRankDeficient,
  kQpInfeasible,
  kQpIterationLimit,
  kNothingToDisplay,
  kTimeWentBackwards,
  kBadConfig,
};

inline constexpr int kStatusCount = static_cast<int>(Status::kBadConfig) + 1;

// Stable snake_case names: they appear in logs, the JSON CLI and the protocol.
constexpr const char* status_name(Status s) {
  switch (s) {
    case Status::kOk:
      return "ok";
    case Status::kNonFiniteInput:
      return "non_finite_input";
    case Status::kBadContactCount:
      return "bad_contact_count";
    case Status::kBadAxis:
      return "bad_axis";
    case Status::kBadQuaternion:
      return "bad_quaternion";
    case Status::kCoincidentContacts:
      return "coincident_contacts";
    case Status::kImpreciseContacts:
      return "imprecise_contacts";
    case Status::kZeroWrench:
      return "zero_wrench";
    case Status::kZeroForce:
      return "zero_force";
    case Status::kRankDeficient:
      return "rank_deficient";
    case Status::kQpInfeasible:
      return "qp_infeasible";
    case Status::kQpIterationLimit:
      return "qp_iteration_limit";
    case Status::kNothingToDisplay:
      return "nothing_to_display";
    case Status::kTimeWentBackwards:
      return "time_went_backwards";
    case Status::kBadConfig:
      return "bad_config";
  }
  return "unknown";
}

// What is wrong and how to fix it, for people reading an error.
constexpr const char* status_message(Status s) {
  switch (s) {
    case Status::kOk:
      return "ok";
    case Status::kNonFiniteInput:
      return "an input is NaN or infinite; check the tracker data and the wrench";
    case Status::kBadContactCount:
      return "the scene needs 3 contacts (thumb, index, middle) or 4 (plus palm)";
    case Status::kBadAxis:
      return "y_axis must be a finite, non-zero vector (default [0, 1, 0])";
    case Status::kBadQuaternion:
      return "orientation must be a finite, non-zero quaternion [w, x, y, z]";
    case Status::kCoincidentContacts:
      return "two contacts (or a contact and the centroid) coincide; check the tracked positions";
    case Status::kImpreciseContacts:
      return "the contacts are so far from the origin that this precision cannot resolve the "
             "hand; send positions relative to a point near the hand (e.g. the palm)";
    case Status::kZeroWrench:
      return "the wrench is zero; give the virtual object a non-zero force";
    case Status::kZeroForce:
      return "the wrench has no force part, so there is no direction to align with gravity";
    case Status::kRankDeficient:
      return "the contacts are (nearly) collinear, so the grasp cannot resist every wrench; "
             "spread the contacts out";
    case Status::kQpInfeasible:
      return "no contact forces satisfy the constraint model for this wrench";
    case Status::kQpIterationLimit:
      return "the QP solver hit its iteration cap; raise max_iterations or report the scene";
    case Status::kNothingToDisplay:
      return "every motor level is zero for this policy; try policy F";
    case Status::kTimeWentBackwards:
      return "timestamps must not decrease within a trial";
    case Status::kBadConfig:
      return "a trial parameter is out of range: 0 <= threshold_deg <= 180, "
             "0 <= hold_s <= 600 and hold_s <= timeout_s, 0 < timeout_s <= 1800 "
             "(max_iterations >= 1)";
  }
  return "unknown status";
}

}  // namespace graspguide
