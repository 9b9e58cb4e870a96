// The trial as a pure state machine on injected timestamps (no clock inside): success once
// the error has stayed within the threshold for the hold time, failure at the timeout
// (reported as exactly the timeout, as in the paper).
#pragma once

#include <stdint.h>

#include "graspguide_cue/status.h"
#include "graspguide_cue/trial_config.h"

namespace graspguide {

enum class TrialState : uint8_t { kIdle = 0, kRunning, kSucceeded, kFailed };

struct TrialResult {
  bool success = false;
  double completion_s = 0;    // time from start to the end of the trial
  double first_entry_s = -1;  // first time the error was within the threshold (-1: never)
  double final_error_deg = 0;
};

class Trial {
 public:
  Status start(const TrialConfig& config, int64_t t_us) {
    const Status s = validate_trial_config(config);
    if (s != Status::kOk) return s;
    config_ = config;
    hold_us_ = static_cast<int64_t>(config.hold_s * 1e6 + 0.5);
    timeout_us_ = static_cast<int64_t>(config.timeout_s * 1e6 + 0.5);
    start_us_ = last_us_ = t_us;
    entry_us_ = -1;
    result_ = TrialResult{};
    state_ = TrialState::kRunning;
    return Status::kOk;
  }

  // Feed one error sample. Returns kOk (state() tells whether the trial ended) or
  // kTimeWentBackwards / kNonFiniteInput, which leave the state unchanged.
  Status update(int64_t t_us, double error_deg) {
    if (state_ != TrialState::kRunning) return Status::kOk;
    if (t_us < last_us_) return Status::kTimeWentBackwards;
    if (!(error_deg == error_deg)) return Status::kNonFiniteInput;
    last_us_ = t_us;
    const int64_t elapsed = t_us - start_us_;
    result_.final_error_deg = error_deg;
    if (error_deg <= config_.threshold_deg) {
      if (entry_us_ < 0) entry_us_ = t_us;
      if (result_.first_entry_s < 0) result_.first_entry_s = elapsed * 1e-6;
      if (t_us - entry_us_ >= hold_us_ && elapsed <= timeout_us_) {
        finish(true, elapsed);
        return Status::kOk;
      }
    } else {
      entry_us_ = -1;
    }
    if (elapsed >= timeout_us_) finish(false, timeout_us_);
    return Status::kOk;
  }

  void abort() {
    if (state_ == TrialState::kRunning) state_ = TrialState::kIdle;
  }

  // Ends a running trial as timed out whatever its timestamps say: the caller's own clock
  // saw the timeout pass (the device's guard against timestamps that stopped advancing).
  void expire() {
    if (state_ == TrialState::kRunning) finish(false, timeout_us_);
  }

  TrialState state() const { return state_; }
  bool running() const { return state_ == TrialState::kRunning; }
  const TrialResult& result() const { return result_; }

 private:
  void finish(bool success, int64_t elapsed_us) {
    result_.success = success;
    result_.completion_s = elapsed_us * 1e-6;
    state_ = success ? TrialState::kSucceeded : TrialState::kFailed;
  }

  TrialConfig config_;
  TrialState state_ = TrialState::kIdle;
  TrialResult result_;
  int64_t start_us_ = 0, last_us_ = 0, entry_us_ = -1, hold_us_ = 0, timeout_us_ = 0;
};

}  // namespace graspguide
