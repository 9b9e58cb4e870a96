// A push button between a pin and GND, on the internal pull-up, debounced in software: a
// new level counts once it has held for the debounce time, so a bouncing contact gives one
// edge per press.
#pragma once

#include <Arduino.h>

#include "graspguide_hal/hal.h"

namespace graspguide::board {

class DebouncedButton final : public graspguide::hal::Button {
 public:
  DebouncedButton(uint8_t pin, uint32_t debounce_ms) : pin_(pin), debounce_ms_(debounce_ms) {}

  void begin() {
    pinMode(pin_, INPUT_PULLUP);
    candidate_ = down_ = digitalRead(pin_) == LOW;  // held at boot: no press until released
    since_ms_ = millis();
  }

  graspguide::hal::ButtonEdge poll() override {
    const bool level_down = digitalRead(pin_) == LOW;
    const uint32_t now_ms = millis();
    if (level_down != candidate_) {
      candidate_ = level_down;
      since_ms_ = now_ms;
      return graspguide::hal::ButtonEdge::kNone;
    }
    if (candidate_ == down_ || uint32_t(now_ms - since_ms_) < debounce_ms_)
      return graspguide::hal::ButtonEdge::kNone;
    down_ = candidate_;
    return down_ ? graspguide::hal::ButtonEdge::kPressed : graspguide::hal::ButtonEdge::kReleased;
  }

  bool down() const override { return down_; }

 private:
  uint8_t pin_;
  uint32_t debounce_ms_;
  uint32_t since_ms_ = 0;
  bool candidate_ = false;
  bool down_ = false;
};

}  // namespace graspguide::board
