// Stand-in for the Arduino core's Wire (I2C) library: only the default bus object, which the
// IMU libraries' begin functions take as a default argument (Arduino.h says what it proves).
#pragma once

#include "Arduino.h"

class TwoWire {};

extern TwoWire Wire;
