// The IMU health rule: is the IMU fit to guide by? Per sample (stuck, out of range) and per
// poll (stale). Anything but kOk means motors off; the application asks motors_allowed().
#pragma once

#include <stdint.h>

#include "graspguide_cue/scalar_math.h"
#include "graspguide_cue/status.h"

// Stale: no sample for this long. Half the pose watchdog's 200 ms, so the host-less mode stops
// the motors no later than the tracker-driven one; at 100 Hz it lets 9 samples go missing (an
// I2C retry or a fusion chip's clock stretching) before it calls the IMU dead.
#ifndef GRASPGUIDE_IMU_STALE_MS
#define GRASPGUIDE_IMU_STALE_MS 100
#endif

// Stuck: the same reading on all six channels this many samples in a row. A live MEMS part's
// noise moves at least one channel by an LSB almost every sample (several LSB rms on each
// axis), while a dead bus or a frozen part repeats its last value or zeros. 20 samples is
// 200 ms at 100 Hz, the pose watchdog's delay. Raise it for a part read faster than it
// converts (every repeat counts).
#ifndef GRASPGUIDE_IMU_STUCK_SAMPLES
#define GRASPGUIDE_IMU_STUCK_SAMPLES 20
#endif

// After any fault, this many good samples in a row before the motors may run again: a
// connector that drops every few samples keeps the motors off instead of flickering them at
// the sample rate. 10 samples is 100 ms at 100 Hz.
#ifndef GRASPGUIDE_IMU_RECOVERY_SAMPLES
#define GRASPGUIDE_IMU_RECOVERY_SAMPLES 10
#endif

namespace graspguide {

// The largest stale time accepted: the elapsed time is read as a signed 32-bit difference of
// microsecond ticks (below), and a watchdog of more than a minute protects nobody.
constexpr uint32_t kImuMaxStaleMs = 60000;

template <typename T>
struct ImuWatchdogConfig {
  uint32_t stale_ms = GRASPGUIDE_IMU_STALE_MS;
  uint16_t stuck_samples = GRASPGUIDE_IMU_STUCK_SAMPLES;
  uint16_t recovery_samples = GRASPGUIDE_IMU_RECOVERY_SAMPLES;
  // The part's configured ranges (the board's Imu reports them): no healthy reading exceeds
  // them, so a larger one is a wrong scale or a corrupted transfer, not a measurement.
  T accel_full_scale_mps2 = T(0);
  T gyro_full_scale_radps = T(0);
};

template <typename T>
Status validate_imu_watchdog_config(const ImuWatchdogConfig<T>& c) {
  const bool ok = c.stale_ms >= 1 && c.stale_ms <= kImuMaxStaleMs && c.stuck_samples >= 2 &&
                  c.recovery_samples >= 1 && scalar_math::is_finite(c.accel_full_scale_mps2) &&
                  c.accel_full_scale_mps2 > T(0) &&
                  scalar_math::is_finite(c.gyro_full_scale_radps) && c.gyro_full_scale_radps > T(0);
  return ok ? Status::kOk : Status::kBadImuConfig;
}

// How often each fault began (an onset, not every sample it lasted).
struct ImuFaultCounts {
  uint32_t stale = 0;
  uint32_t stuck = 0;
  uint32_t out_of_range = 0;
};

// Timestamps are ticks of the board's free-running 32-bit microsecond clock (micros() wraps
// every 71.6 min). Elapsed time is the signed difference, so a sample stamped just after a
// poll's "now" never reads as ancient; poll at least every 35 minutes (2^31 us), which any
// control loop does. A stale fault, once raised, lasts until the next sample, however long.
template <typename T>
class ImuWatchdog {
 public:
  // Starts with no sample: kImuStale (not counted) until recovery_samples good samples come.
  // An invalid config makes every decision kBadImuConfig, so the motors never run on it.
  ImuWatchdog(const ImuWatchdogConfig<T>& config, uint32_t now_us)
      : config_(config), config_status_(validate_imu_watchdog_config(config)) {
    restart(now_us);
  }

  // Forgets the history (keeps the counts): as at construction, from now_us.
  void restart(uint32_t now_us) {
    last_sample_us_ = now_us;
    stale_ = stuck_ = out_of_range_ = false;
    have_previous_ = false;
    repeats_ = 0;
    good_run_ = 0;
    status_ = config_status_ == Status::kOk ? Status::kImuStale : config_status_;
  }

  // One sample: accelerometer (or a fusion chip's gravity) in m/s^2 and gyroscope in rad/s,
  // stamped with the board's clock when it was read.
  Status on_sample(const T (&accel_mps2)[3], const T (&gyro_radps)[3], uint32_t time_us) {
    if (config_status_ != Status::kOk) return status_;
    ++samples_;
    last_sample_us_ = time_us;
    stale_ = false;

    bool in_range = true;
    bool same = have_previous_;
    for (int i = 0; i < 3; ++i) {
      in_range = in_range && within(accel_mps2[i], config_.accel_full_scale_mps2) &&
                 within(gyro_radps[i], config_.gyro_full_scale_radps);
      // Exact comparison on purpose: the same raw counts convert to the same float.
      same = same && accel_mps2[i] == previous_[i] && gyro_radps[i] == previous_[3 + i];
      previous_[i] = accel_mps2[i];
      previous_[3 + i] = gyro_radps[i];
    }
    have_previous_ = true;
    repeats_ = same ? (repeats_ < 0xFFFF ? uint16_t(repeats_ + 1) : repeats_) : uint16_t(1);

    const bool stuck_now = repeats_ >= config_.stuck_samples;
    if (stuck_now && !stuck_) ++counts_.stuck;
    stuck_ = stuck_now;
    if (!in_range && !out_of_range_) ++counts_.out_of_range;
    out_of_range_ = !in_range;

    if (out_of_range_ || stuck_) {
      good_run_ = 0;
      status_ = out_of_range_ ? Status::kImuOutOfRange : Status::kImuStuck;
    } else if (status_ != Status::kOk && ++good_run_ >= config_.recovery_samples) {
      status_ = Status::kOk;
    }
    return status_;
  }

  // The time check, once per control loop.
  Status poll(uint32_t now_us) {
    if (config_status_ != Status::kOk) return status_;
    const int32_t elapsed_us = static_cast<int32_t>(now_us - last_sample_us_);
    if (!stale_ && elapsed_us >= static_cast<int32_t>(config_.stale_ms * 1000u)) {
      stale_ = true;
      ++counts_.stale;
      good_run_ = 0;
      status_ = Status::kImuStale;
    }
    return status_;
  }

  // The decision: kOk, or the fault that holds the motors off (the latest one).
  Status status() const { return status_; }
  bool motors_allowed() const { return status_ == Status::kOk; }
  const ImuFaultCounts& faults() const { return counts_; }
  uint32_t samples() const { return samples_; }

 private:
  static bool within(T x, T full_scale) { return scalar_math::abs_of(x) <= full_scale; }

  ImuWatchdogConfig<T> config_;
  Status config_status_;
  Status status_ = Status::kImuStale;
  uint32_t last_sample_us_ = 0;
  uint32_t samples_ = 0;
  ImuFaultCounts counts_;
  T previous_[6] = {};
  uint16_t repeats_ = 0;
  uint16_t good_run_ = 0;
  bool have_previous_ = false;
  bool stale_ = false;
  bool stuck_ = false;
  bool out_of_range_ = false;
};

}  // namespace graspguide
