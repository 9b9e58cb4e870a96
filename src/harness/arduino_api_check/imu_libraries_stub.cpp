// Definitions behind the stand-in IMU libraries and Wire: enough to link, never run.
// Every begin fails, as with no part on the bus.
#include "Adafruit_BNO055.h"
#include "Adafruit_LSM6DSOX.h"
#include "Wire.h"

TwoWire Wire;

bool Adafruit_LSM6DS::begin_I2C(uint8_t, TwoWire*, int32_t) { return false; }
bool Adafruit_LSM6DS::getEvent(sensors_event_t*, sensors_event_t*, sensors_event_t*) {
  return false;
}
void Adafruit_LSM6DS::setAccelDataRate(lsm6ds_data_rate_t) {}
void Adafruit_LSM6DS::setAccelRange(lsm6ds_accel_range_t) {}
void Adafruit_LSM6DS::setGyroDataRate(lsm6ds_data_rate_t) {}
void Adafruit_LSM6DS::setGyroRange(lsm6ds_gyro_range_t) {}

Adafruit_BNO055::Adafruit_BNO055(int32_t, uint8_t, TwoWire*) {}
bool Adafruit_BNO055::begin(adafruit_bno055_opmode_t) { return false; }
void Adafruit_BNO055::setExtCrystalUse(boolean) {}
bool Adafruit_BNO055::getEvent(sensors_event_t*, adafruit_vector_type_t) { return false; }
