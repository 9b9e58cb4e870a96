// GraspGuide's per-frame layer: what a tracker frame needs while the posture stays the same
// (guidance error, alpha, PWM, trial, watchdog). Plain C++14 with only <math.h>, <stdint.h>
// and <float.h>, so the same source builds for an 8-bit AVR and for the core. See
// docs/per-frame-layer.md.
#pragma once

#include "graspguide_cue/alignment.h"
#include "graspguide_cue/pwm.h"
#include "graspguide_cue/status.h"
#include "graspguide_cue/trial.h"
#include "graspguide_cue/trial_clock.h"
#include "graspguide_cue/watchdog.h"
