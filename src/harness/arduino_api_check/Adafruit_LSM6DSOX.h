// Stand-in for Adafruit_LSM6DSOX.h of Adafruit's LSM6DS library (Adafruit_LSM6DS.h says why).
#pragma once

#include "Adafruit_LSM6DS.h"

class Adafruit_LSM6DSOX : public Adafruit_LSM6DS {};
