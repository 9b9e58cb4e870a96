// The wearable controller's Arduino entry point: wires the board's serial ports, clock
// and motor outputs to the portable device application (lib/graspguide_device) and polls
// it. Everything that decides anything lives there and is tested on the host.
#include <Arduino.h>

#include "arduino_hal.h"
#include "board_config.h"
#include "esp32_ledc_motors.h"
#include "graspguide_device/link_device.h"

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
}

void loop() {
  usb_link.poll();
#if GRASPGUIDE_USE_BLUETOOTH
  bt_link.poll();
#endif
}
