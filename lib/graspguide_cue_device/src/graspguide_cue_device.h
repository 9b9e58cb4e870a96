// GraspGuide's per-frame-only device: the link subset a board speaks when the host solves
// each posture, and the device loop over it. See docs/per-frame-layer.md.
#pragma once

#include "graspguide_cue_device/device.h"
#include "graspguide_cue_device/link_subset.h"
#include "graspguide_cue_device/parser.h"
#include "graspguide_hal.h"
