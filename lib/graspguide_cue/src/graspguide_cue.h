// GraspGuide's per-frame layer: what a tracker frame needs while the posture stays the same
// (guidance error, alpha, PWM, trial, watchdog). Plain C++14 with only <math.h>, <stdint.h>
// and <float.h>, so the same source builds for an 8-bit AVR and for the core. See
// docs/per-frame-layer.md.
#pragma once

#include "graspguide_frame/alignment.h"
#include "graspguide_frame/pwm.h"
#include "graspguide_frame/status.h"
#include "graspguide_frame/trial.h"
#include "graspguide_frame/trial_clock.h"
#include "graspguide_frame/watchdog.h"
