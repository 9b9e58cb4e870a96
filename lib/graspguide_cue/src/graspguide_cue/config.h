// Build-time constants of the per-frame layer; the macros can be overridden from
// build_flags (e.g. -DGRASPGUIDE_PWM_MIN=60).
#pragma once

// PWM of the paper's motors (Precision Microdrives 310-103 at 3.3 V): 70 is the lowest
// duty that still spins the ERM, 70 + 185 = 255 is full scale.
#ifndef GRASPGUIDE_PWM_MIN
#define GRASPGUIDE_PWM_MIN 70
#endif
#ifndef GRASPGUIDE_PWM_SPAN
#define GRASPGUIDE_PWM_SPAN 185
#endif

namespace graspguide {

// Namespace-scope constexpr, not C++17 inline variables: avr-gcc 5.4 is C++14.
constexpr int kPwmMin = GRASPGUIDE_PWM_MIN;
constexpr int kPwmSpan = GRASPGUIDE_PWM_SPAN;
static_assert(kPwmMin >= 0 && kPwmSpan >= 0 && kPwmMin + kPwmSpan <= 255, "8-bit PWM");

constexpr int kMinContacts = 3;
constexpr int kMaxContacts = 4;

}  // namespace graspguide
