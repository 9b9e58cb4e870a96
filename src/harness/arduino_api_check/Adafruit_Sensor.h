// Stand-in for Adafruit's Unified Sensor library (a dependency of the IMU libraries): the
// event fields the board code reads, by their real names and types. The real event holds
// them in unions; member access is the same. Arduino.h says what this proves.
#pragma once

#include "Arduino.h"

typedef struct {
  float x;
  float y;
  float z;
} sensors_vec_t;

typedef struct {
  int32_t timestamp;
  sensors_vec_t acceleration;  // m/s^2
  sensors_vec_t gyro;          // rad/s
} sensors_event_t;
