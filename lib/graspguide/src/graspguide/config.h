// Build-time configuration of the core. Every value can be overridden from
// platformio.ini `build_flags` (e.g. -DGRASPGUIDE_USE_DOUBLE=1).
#pragma once

#ifndef GRASPGUIDE_USE_DOUBLE
#define GRASPGUIDE_USE_DOUBLE 0  // microcontrollers with a single-precision FPU
#endif

namespace graspguide {

// The one precision switch: the scalar the firmware and tools run with by default.
// All algorithms are templates on the scalar, so tests can compare both in one binary.
#if GRASPGUIDE_USE_DOUBLE
using Real = double;
#else
using Real = float;
#endif

// PWM of the paper's motors (Precision Microdrives 310-103 at 3.3 V): 70 is the lowest
// duty that still spins the ERM, 70 + 185 = 255 is full scale.
#ifndef GRASPGUIDE_PWM_MIN
#define GRASPGUIDE_PWM_MIN 70
#endif
#ifndef GRASPGUIDE_PWM_SPAN
#define GRASPGUIDE_PWM_SPAN 185
#endif
inline constexpr int kPwmMin = GRASPGUIDE_PWM_MIN;
inline constexpr int kPwmSpan = GRASPGUIDE_PWM_SPAN;
static_assert(kPwmMin >= 0 && kPwmSpan >= 0 && kPwmMin + kPwmSpan <= 255, "8-bit PWM");

inline constexpr int kMinContacts = 3;
inline constexpr int kMaxContacts = 4;

}  // namespace graspguide
