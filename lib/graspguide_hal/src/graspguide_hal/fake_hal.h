// In-memory hardware for tests and host tools, for either device library: a clock set by
// hand, motors that record every write, an IMU and a button fed by the test, and a serial
// stream of two queues.
#pragma once

#include <string.h>

#include "graspguide_hal/hal.h"

namespace graspguide {
namespace hal {

class FakeClock final : public Clock {
 public:
  uint32_t now_us() override { return now_us_; }
  void set_us(uint32_t t) { now_us_ = t; }
  void advance_us(uint32_t dt) { now_us_ += dt; }

 private:
  uint32_t now_us_ = 0;
};

class RecordingMotors final : public MotorOutputs {
 public:
  void write(const Pwm& pwm) override {
    last_ = pwm;
    ++writes_;
  }
  const Pwm& last() const { return last_; }
  bool all_off() const {
    for (uint8_t d : last_.duty)
      if (d != 0) return false;
    return true;
  }
  uint32_t writes() const { return writes_; }

 private:
  Pwm last_;
  uint32_t writes_ = 0;
};

// An IMU whose next sample the test sets; read() hands it out once.
class FakeImu final : public Imu {
 public:
  FakeImu(ImuOutput output, float accel_full_scale_mps2, float gyro_full_scale_radps)
      : output_(output), accel_fs_(accel_full_scale_mps2), gyro_fs_(gyro_full_scale_radps) {}

  ImuOutput output() const override { return output_; }
  float accel_full_scale_mps2() const override { return accel_fs_; }
  float gyro_full_scale_radps() const override { return gyro_fs_; }

  void push(const ImuSample& s) {
    next_ = s;
    ready_ = true;
  }
  bool read(ImuSample& out) override {
    if (!ready_) return false;
    out = next_;
    ready_ = false;
    ++reads_;
    return true;
  }
  uint32_t reads() const { return reads_; }

 private:
  ImuOutput output_;
  float accel_fs_, gyro_fs_;
  ImuSample next_;
  bool ready_ = false;
  uint32_t reads_ = 0;
};

// A button already debounced: the test presses and releases it, each poll reports one edge.
class FakeButton final : public Button {
 public:
  void press() { pending_ = down_ ? pending_ : ButtonEdge::kPressed; }
  void release() { pending_ = down_ ? ButtonEdge::kReleased : pending_; }
  ButtonEdge poll() override {
    const ButtonEdge e = pending_;
    pending_ = ButtonEdge::kNone;
    if (e != ButtonEdge::kNone) down_ = e == ButtonEdge::kPressed;
    return e;
  }
  bool down() const override { return down_; }

 private:
  ButtonEdge pending_ = ButtonEdge::kNone;
  bool down_ = false;
};

// Two in-memory queues: what the host sends (read by the device) and what the device
// writes (read by the test), with fixed capacities.
class MemoryStream final : public ByteStream {
 public:
  static constexpr size_t kCapacity = 1 << 14;

  // Host side.
  bool host_send(const uint8_t* data, size_t n) {
    if (in_size_ + n > kCapacity) return false;
    memcpy(in_ + in_size_, data, n);
    in_size_ += n;
    return true;
  }
  size_t host_receive(uint8_t* out, size_t capacity) {
    const size_t n = out_size_ < capacity ? out_size_ : capacity;
    memcpy(out, out_, n);
    memmove(out_, out_ + n, out_size_ - n);
    out_size_ -= n;
    return n;
  }

  // Device side.
  size_t read(uint8_t* buffer, size_t capacity) override {
    const size_t n = in_size_ - in_read_ < capacity ? in_size_ - in_read_ : capacity;
    memcpy(buffer, in_ + in_read_, n);
    in_read_ += n;
    if (in_read_ == in_size_) in_read_ = in_size_ = 0;
    return n;
  }
  size_t write(const uint8_t* data, size_t length) override {
    const size_t n = out_size_ + length > kCapacity ? kCapacity - out_size_ : length;
    memcpy(out_ + out_size_, data, n);
    out_size_ += n;
    return n;
  }

 private:
  uint8_t in_[kCapacity] = {};
  uint8_t out_[kCapacity] = {};
  size_t in_size_ = 0, in_read_ = 0, out_size_ = 0;
};

}  // namespace hal
}  // namespace graspguide
