// The wearable controller's Arduino entry point: wires the board's serial ports, clock
// and motor outputs to the portable device application (lib/graspguide_device) and polls
// it. Everything that decides anything lives there and is tested on the host.
#include <Arduino.h>

#include "arduino_hal.h"
#include "board_config.h"
#include "debounced_button.h"
#include "esp32_ledc_motors.h"
#include "graspguide_device/link_device.h"
#include "graspguide_frame/imu_watchdog.h"

#if GRASPGUIDE_IMU == GRASPGUIDE_IMU_LSM6DSOX
#include "lsm6dsox_imu.h"
#elif GRASPGUIDE_IMU == GRASPGUIDE_IMU_BNO055
#include "bno055_imu.h"
#elif GRASPGUIDE_IMU != GRASPGUIDE_IMU_NONE
#error \
    "GRASPGUIDE_IMU must be GRASPGUIDE_IMU_NONE, GRASPGUIDE_IMU_LSM6DSOX or GRASPGUIDE_IMU_BNO055"
#endif

#if GRASPGUIDE_USE_BLUETOOTH
#include <BluetoothSerial.h>
#endif

namespace {

namespace gb = graspguide::board;
namespace gd = graspguide::device;

constexpr uint8_t kMotorPins[graspguide::kMaxContacts] = {GRASPGUIDE_MOTOR_PINS};

// Constructed before setup() runs: the pins are driven low at static initialisation.
#if defined(ARDUINO_ARCH_ESP32)
gb::Esp32LedcMotors<graspguide::kMaxContacts> motors(kMotorPins);
#else
gb::AnalogWriteMotors<graspguide::kMaxContacts> motors(kMotorPins);
#endif

gb::MicrosClock clock_us;
gd::Application app(motors, clock_us);
gd::DeviceInfo board_info() {
  gd::DeviceInfo i;
  i.board = GRASPGUIDE_BOARD_NAME;
  i.build_id = GRASPGUIDE_BUILD_ID;
  return i;
}
// Links copy it when they are built, below.
const gd::DeviceInfo info = board_info();

gb::SerialByteStream usb_stream(Serial, /*check_space=*/true);
gd::LinkDevice usb_link(usb_stream, app, info);

// The IMU and the button are read and the IMU's health decided every loop, but in this
// tracker-driven firmware nothing acts on them yet: the host-less mode (issue 13) gates its
// motors on imu_health.motors_allowed() and starts trials on a press. A board without an IMU
// keeps working as before (its IMU is simply stale).
#if GRASPGUIDE_IMU == GRASPGUIDE_IMU_LSM6DSOX
gb::Lsm6dsoxImu imu(clock_us, GRASPGUIDE_IMU_PERIOD_US);
#elif GRASPGUIDE_IMU == GRASPGUIDE_IMU_BNO055
gb::Bno055Imu imu(clock_us, GRASPGUIDE_IMU_PERIOD_US);
#endif
#if GRASPGUIDE_IMU != GRASPGUIDE_IMU_NONE
graspguide::ImuWatchdogConfig<float> imu_health_config() {
  graspguide::ImuWatchdogConfig<float> c;
  c.accel_full_scale_mps2 = imu.accel_full_scale_mps2();
  c.gyro_full_scale_radps = imu.gyro_full_scale_radps();
  return c;
}
graspguide::ImuWatchdog<float> imu_health(imu_health_config(), 0);

void poll_imu() {
  gd::ImuSample s;
  if (imu.read(s)) imu_health.on_sample(s.accel_mps2, s.gyro_radps, s.time_us);
  imu_health.poll(clock_us.now_us());
}
#endif

gb::DebouncedButton button(GRASPGUIDE_BUTTON_PIN, GRASPGUIDE_BUTTON_DEBOUNCE_MS);

#if GRASPGUIDE_USE_BLUETOOTH
BluetoothSerial bt_port;
gb::SerialByteStream bt_stream(bt_port, /*check_space=*/false);
// Each link has its own parser and answers its own requests; both drive one application,
// so a STOP from either ends whatever the other started.
gd::LinkDevice bt_link(bt_stream, app, info);
#endif

}  // namespace

void setup() {
#if defined(ARDUINO_ARCH_ESP32)
  motors.begin(GRASPGUIDE_PWM_FREQUENCY_HZ, GRASPGUIDE_PWM_RESOLUTION_BITS);
#else
  motors.begin(GRASPGUIDE_PWM_FREQUENCY_HZ);
#endif
  app.stop();  // state STOPPED, motors written off once more through the application
  Serial.begin(GRASPGUIDE_SERIAL_BAUD);
#if GRASPGUIDE_USE_BLUETOOTH
  bt_port.begin(GRASPGUIDE_BT_NAME);
#endif
#if GRASPGUIDE_IMU != GRASPGUIDE_IMU_NONE
  imu.begin();  // no IMU answering is not an error here: the health rule reports it stale
  imu_health.restart(clock_us.now_us());
#endif
  button.begin();
}

void loop() {
  usb_link.poll();
#if GRASPGUIDE_USE_BLUETOOTH
  bt_link.poll();
#endif
#if GRASPGUIDE_IMU != GRASPGUIDE_IMU_NONE
  poll_imu();
#endif
  button.poll();  // debounced every loop, so its edges are ready when a consumer comes
}
