// The GraspGuide core: Algorithm 1 of "Hand Guidance Using Grasping Metaphor and Wearable
// Haptics" on fixed-size Eigen types, portable to microcontrollers (no heap, no
// exceptions, no Arduino.h). See docs/algorithm.md.
#pragma once

#include "graspguide/guidance.h"
#include "graspguide_cue/trial.h"
