// setup() and loop(): wiring only; everything the board decides is in the device.
#include <Arduino.h>

// board_glue.h first: it names the libraries in the order arduino-cli must find them.
#include "board_glue.h"

// The first 8 hex digits of the commit it was built from, stamped by the build
// (graspguide.promini.build, `pio run -e promini`); 0 from a build that does not stamp it.
#ifndef GRASPGUIDE_BUILD_ID
#define GRASPGUIDE_BUILD_ID 0u
#endif

namespace {

graspguide::promini::SerialStream g_stream;
graspguide::promini::PwmMotors g_motors;
graspguide::promini::MicrosClock g_clock;
graspguide::cue_device::CueDevice* g_device = nullptr;

}  // namespace

void setup() {
  // Motors off before anything else can fail or wait.
  g_motors.begin();
  Serial.begin(graspguide::promini::kBaud);
  graspguide::cue_device::DeviceInfo info;
  info.build_id = GRASPGUIDE_BUILD_ID;
  // Built here, not as a global, so its first motor write finds the pins already set up.
  static graspguide::cue_device::CueDevice device(g_stream, g_motors, g_clock, info);
  g_device = &device;
}

// GPIOR0 is a spare register no code here uses: 1 before a poll and 2 after one that
// completed a frame let the simavr runner (--marks) count the cycles of decode + frame +
// TELEMETRY encode; on a board the two writes cost a cycle each.
void loop() {
  const uint32_t frames = g_device->parser().good_frames();
  GPIOR0 = 1;
  g_device->poll();
  if (g_device->parser().good_frames() != frames) GPIOR0 = 2;
}
