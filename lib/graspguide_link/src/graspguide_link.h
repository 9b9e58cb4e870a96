// The whole GraspGuide link library: framing, parser, writer and the generated messages.
#pragma once

#include "graspguide_link/byte_order.h"
#include "graspguide_link/cobs.h"
#include "graspguide_link/crc16.h"
#include "graspguide_link/frame.h"
#include "graspguide_link/link_status.h"
#include "graspguide_link/messages.h"
#include "graspguide_link/parser.h"
#include "graspguide_link/writer.h"
