// Stand-in for Adafruit's BNO055 library (adafruit/Adafruit BNO055): the calls
// src/boards/arduino/bno055_imu.h makes, with the library's signatures and enum values.
// Arduino.h says what this proves.
#pragma once

#include "Adafruit_Sensor.h"
#include "Arduino.h"
#include "Wire.h"

#define BNO055_ADDRESS_A (0x28)

typedef enum { OPERATION_MODE_IMUPLUS = 0X08, OPERATION_MODE_NDOF = 0X0C } adafruit_bno055_opmode_t;

class Adafruit_BNO055 {
 public:
  typedef enum { VECTOR_GYROSCOPE = 0X14, VECTOR_GRAVITY = 0X2E } adafruit_vector_type_t;

  Adafruit_BNO055(int32_t sensorID = -1, uint8_t address = BNO055_ADDRESS_A,
                  TwoWire* theWire = &Wire);

  bool begin(adafruit_bno055_opmode_t mode = OPERATION_MODE_NDOF);
  void setExtCrystalUse(boolean usextal);
  bool getEvent(sensors_event_t*, adafruit_vector_type_t);
};
