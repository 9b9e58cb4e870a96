// The wearable controller's Arduino entry point: wires the board's serial ports, clock,
// motor outputs, IMU, button and (host-less builds) non-volatile store to the portable
// device code (lib/graspguide_device) and polls it. Everything that decides anything lives
// there and is tested on the host.
#include <Arduino.h>

#include "arduino_hal.h"
#include "board_config.h"
#include "debounced_button.h"
#include "esp32_ledc_motors.h"
#include "graspguide_cue/imu_watchdog.h"
#include "graspguide_device/link_device.h"

#if GRASPGUIDE_IMU == GRASPGUIDE_IMU_LSM6DSOX
#include "lsm6dsox_imu.h"
#elif GRASPGUIDE_IMU == GRASPGUIDE_IMU_BNO055
#include "bno055_imu.h"
#elif GRASPGUIDE_IMU != GRASPGUIDE_IMU_NONE
#error \
    "GRASPGUIDE_IMU must be GRASPGUIDE_IMU_NONE, GRASPGUIDE_IMU_LSM6DSOX or GRASPGUIDE_IMU_BNO055"
#endif

#if GRASPGUIDE_HOSTLESS
#if GRASPGUIDE_IMU == GRASPGUIDE_IMU_NONE
#error "GRASPGUIDE_HOSTLESS=1 needs an IMU: set GRASPGUIDE_IMU to LSM6DSOX or BNO055"
#endif
#if !defined(ARDUINO_ARCH_ESP32)
#error "GRASPGUIDE_HOSTLESS=1 needs the ESP32's LittleFS; this board has no store for a plan"
#endif
#include "littlefs_storage.h"
#endif

#if GRASPGUIDE_USE_BLUETOOTH
#include <BluetoothSerial.h>
#endif

#if defined(ARDUINO_ARCH_ESP32)
// The loop task's stack, 8 KB by default: a posture float cannot vouch for is solved again
// in double (docs/algorithm.md, step 5), and that took the Cortex-M4F firmware's stack
// peak to 7.4 KB under QEMU (tools/tests/test_qemu_firmware.py).
SET_LOOP_TASK_STACK_SIZE(16 * 1024);
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
  // Never kCapabilitySimMessages: a real board has its own IMU and button, so LinkDevice
  // answers SIM_IMU_SAMPLE and SIM_BUTTON with sim_only.
#if GRASPGUIDE_HOSTLESS
  i.capabilities = uint8_t(i.capabilities | graspguide::link::kCapabilityHostless);
#endif
  return i;
}
// Links copy it when they are built, below.
const gd::DeviceInfo info = board_info();

#if GRASPGUIDE_IMU == GRASPGUIDE_IMU_LSM6DSOX
gb::Lsm6dsoxImu imu(clock_us, GRASPGUIDE_IMU_PERIOD_US);
#elif GRASPGUIDE_IMU == GRASPGUIDE_IMU_BNO055
gb::Bno055Imu imu(clock_us, GRASPGUIDE_IMU_PERIOD_US);
#endif

gb::DebouncedButton button(GRASPGUIDE_BUTTON_PIN, GRASPGUIDE_BUTTON_DEBOUNCE_MS);

#if GRASPGUIDE_HOSTLESS
static_assert(GRASPGUIDE_STORE_BYTES >=
                  gd::kPlanRegionBytes + uint32_t(gd::kMaxPlanTrials) * gd::kLogSlotBytes,
              "GRASPGUIDE_STORE_BYTES must hold the plan region and a full plan's records");
gb::LittleFsStorage store(GRASPGUIDE_STORE_PATH, GRASPGUIDE_STORE_BYTES);
// The IMU's own health rule (stale, stuck, out of range) lives in the runner and gates its
// motors; its ranges are the ones the driver set the part to.
gd::HostlessRunner hostless(motors, clock_us, store, imu.output(), imu.accel_full_scale_mps2(),
                            imu.gyro_full_scale_radps());
gd::HostlessRunner* const hostless_link = &hostless;

void poll_hostless() {
  graspguide::hal::ImuSample s;
  if (imu.read(s)) hostless.on_sample(s);
  const graspguide::hal::ButtonEdge edge = button.poll();
  if (edge != graspguide::hal::ButtonEdge::kNone)
    hostless.on_button(edge == graspguide::hal::ButtonEdge::kPressed, clock_us.now_us());
  // The links tick the runner too; this one keeps its timers going whatever the links do.
  hostless.tick(clock_us.now_us());
}
#else
gd::HostlessRunner* const hostless_link = nullptr;
#endif

// Both links take the plan and log requests, and both refuse tracker-driven requests while
// a plan runs, so neither host can fight the wearer's trial for the motors. The run's
// events go out on whichever link polls first (USB).
gb::SerialByteStream usb_stream(Serial, /*check_space=*/true);
gd::LinkDevice usb_link(usb_stream, app, info, nullptr, hostless_link);

// Without the host-less mode the IMU is still read and judged every loop, so a board
// reports a broken IMU the same way, but nothing acts on it: guidance needs a host's poses.
#if GRASPGUIDE_IMU != GRASPGUIDE_IMU_NONE && !GRASPGUIDE_HOSTLESS
graspguide::ImuWatchdogConfig<float> imu_health_config() {
  graspguide::ImuWatchdogConfig<float> c;
  c.accel_full_scale_mps2 = imu.accel_full_scale_mps2();
  c.gyro_full_scale_radps = imu.gyro_full_scale_radps();
  return c;
}
graspguide::ImuWatchdog<float> imu_health(imu_health_config(), 0);

void poll_imu() {
  graspguide::hal::ImuSample s;
  if (imu.read(s)) imu_health.on_sample(s.accel_mps2, s.gyro_radps, s.time_us);
  imu_health.poll(clock_us.now_us());
}
#endif

#if GRASPGUIDE_USE_BLUETOOTH
BluetoothSerial bt_port;
gb::SerialByteStream bt_stream(bt_port, /*check_space=*/false);
// Each link has its own parser and answers its own requests; both drive one application,
// so a STOP from either ends whatever the other started.
gd::LinkDevice bt_link(bt_stream, app, info, nullptr, hostless_link);
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
  // No IMU answering is not an error here: the health rule reports it stale.
  const bool imu_found = imu.begin();
#endif
#if GRASPGUIDE_IMU != GRASPGUIDE_IMU_NONE && !GRASPGUIDE_HOSTLESS
  (void)imu_found;
  imu_health.restart(clock_us.now_us());
#endif
  button.begin();
#if GRASPGUIDE_HOSTLESS
  // A store that did not open leaves the runner with no room: boot() finds no plan, and the
  // host's plan and log requests are answered storage_failed or no_plan.
  store.begin();
  hostless.boot();
  // A stored plan runs at power-up: the wearable needs no host. Not with no IMU answering:
  // every trial would time out with its motors off and use up the plan's records.
  if (imu_found && hostless.plan_stored()) hostless.start();
#endif
}

void loop() {
  usb_link.poll();
#if GRASPGUIDE_USE_BLUETOOTH
  bt_link.poll();
#endif
#if GRASPGUIDE_HOSTLESS
  poll_hostless();
#else
#if GRASPGUIDE_IMU != GRASPGUIDE_IMU_NONE
  poll_imu();
#endif
  button.poll();  // debounced every loop, so its edges are ready when a consumer comes
#endif
}
