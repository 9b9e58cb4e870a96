// Build-time configuration of the core. Every value can be overridden from
// platformio.ini `build_flags` (e.g. -DGRASPGUIDE_USE_DOUBLE=1).
#pragma once

// The PWM range (GRASPGUIDE_PWM_MIN, GRASPGUIDE_PWM_SPAN) and the contact counts.
#include "graspguide_cue/config.h"

#ifndef GRASPGUIDE_USE_DOUBLE
#define GRASPGUIDE_USE_DOUBLE 0  // microcontrollers with a single-precision FPU
#endif

// A float solve that cannot vouch for its answer retries the posture in double
// (answer_certificate.h): once per posture, in software on an FPU without double. 0 keeps
// float's answer, as the benchmark does to measure what the retry buys.
#ifndef GRASPGUIDE_DOUBLE_RETRY
#define GRASPGUIDE_DOUBLE_RETRY 1
#endif

namespace graspguide {

// The one precision switch: the scalar the firmware and tools run with by default.
// All algorithms are templates on the scalar, so tests can compare both in one binary.
#if GRASPGUIDE_USE_DOUBLE
using Real = double;
#else
using Real = float;
#endif

}  // namespace graspguide
