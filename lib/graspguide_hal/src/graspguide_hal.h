// GraspGuide's hardware interfaces (hal.h) and the link's poll loop (link_poll.h), shared
// by lib/graspguide_device and lib/graspguide_cue_device; fake_hal.h holds the
// in-memory fakes the tests use.
#pragma once

#include "graspguide_hal/hal.h"
#include "graspguide_hal/link_poll.h"
