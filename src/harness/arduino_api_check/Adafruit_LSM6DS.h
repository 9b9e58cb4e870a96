// Stand-in for the base class of Adafruit's LSM6DS library (adafruit/Adafruit LSM6DS): the
// calls src/boards/arduino/lsm6dsox_imu.h makes, with the library's signatures and enum
// values. Arduino.h says what this proves.
#pragma once

#include "Adafruit_Sensor.h"
#include "Arduino.h"
#include "Wire.h"

#define LSM6DS_I2CADDR_DEFAULT 0x6A

typedef enum data_rate {
  LSM6DS_RATE_SHUTDOWN,
  LSM6DS_RATE_12_5_HZ,
  LSM6DS_RATE_26_HZ,
  LSM6DS_RATE_52_HZ,
  LSM6DS_RATE_104_HZ,
} lsm6ds_data_rate_t;

typedef enum accel_range {
  LSM6DS_ACCEL_RANGE_2_G,
  LSM6DS_ACCEL_RANGE_16_G,
  LSM6DS_ACCEL_RANGE_4_G,
  LSM6DS_ACCEL_RANGE_8_G
} lsm6ds_accel_range_t;

typedef enum gyro_range {
  LSM6DS_GYRO_RANGE_2000_DPS = 0b1100,
} lsm6ds_gyro_range_t;

class Adafruit_LSM6DS {
 public:
  virtual ~Adafruit_LSM6DS() = default;

  bool begin_I2C(uint8_t i2c_addr = LSM6DS_I2CADDR_DEFAULT, TwoWire* wire = &Wire,
                 int32_t sensorID = 0);
  bool getEvent(sensors_event_t* accel, sensors_event_t* gyro, sensors_event_t* temp);
  void setAccelDataRate(lsm6ds_data_rate_t data_rate);
  void setAccelRange(lsm6ds_accel_range_t new_range);
  void setGyroDataRate(lsm6ds_data_rate_t data_rate);
  void setGyroRange(lsm6ds_gyro_range_t new_range);
};
