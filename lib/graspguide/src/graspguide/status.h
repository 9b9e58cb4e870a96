// The statuses live with the per-frame layer, which an AVR builds without the core; the one
// list is graspguide_cue/status.h.
#pragma once

#include "graspguide_cue/status.h"
