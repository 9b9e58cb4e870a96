"""The board's hardware behind the small interfaces the runner uses (hal.h's roles); the
only module that imports machine. fake_hal has the same interfaces for the unix
interpreter.

  Motors: write(duty) with duty 4 bytes of 8-bit PWM, all motors at once.
  Imu:    read_into(accel, gyro) -> bool, accel_full_scale_mps2(), gyro_full_scale_radps(),
          SIX_AXIS (False for a part that reports fused gravity).
  Button: poll() -> EDGE_NONE / EDGE_PRESSED / EDGE_RELEASED, debounced; down().
  Clock:  now_us() -> ticks (frame.TICKS_PERIOD), now_ms() for the button."""

import time

import machine
from graspguide_mp.frame import MAX_CONTACTS, TICKS_MASK
from graspguide_mp.lsm6dsox import Lsm6dsox

EDGE_NONE = 0
EDGE_PRESSED = 1
EDGE_RELEASED = 2

# An ERM at 1 kHz buzzes audibly; 20 kHz is above hearing and within every port's range.
PWM_FREQ_HZ = 20000
DEBOUNCE_MS = 20  # board_config.h GRASPGUIDE_BUTTON_DEBOUNCE_MS


class Clock:
    def now_us(self):
        # ticks_us's period is 2^30 on 32-bit ports (identity then) and a multiple of it
        # elsewhere, so the mask keeps wrap-around consistent everywhere.
        return time.ticks_us() & TICKS_MASK

    def now_ms(self):
        return time.ticks_ms()

    def ms_since(self, then_ms):
        return time.ticks_diff(time.ticks_ms(), then_ms)


class Motors:
    """machine.PWM per motor; the same 8-bit scale as the C++ (255 = full on, exactly
    65535 in duty_u16), 0 = off. Starts off."""

    def __init__(self, pins, freq_hz=PWM_FREQ_HZ):
        if not 1 <= len(pins) <= MAX_CONTACTS:
            raise ValueError("pins: 1..%d motor pins, got %r" % (MAX_CONTACTS, pins))
        self._pwm = []
        for p in pins:
            pin = machine.Pin(p, machine.Pin.OUT, value=0)
            self._pwm.append(machine.PWM(pin, freq=freq_hz, duty_u16=0))

    def write(self, duty):
        for i in range(len(self._pwm)):
            self._pwm[i].duty_u16(duty[i] * 257)

    def off(self):
        for p in self._pwm:
            p.duty_u16(0)


class Button:
    """A push button between a pin and GND on the internal pull-up, debounced: a new level
    counts once it has held DEBOUNCE_MS, so a bouncing contact gives one edge per press.
    Held at boot: no press until it is released."""

    def __init__(self, pin, clock, debounce_ms=DEBOUNCE_MS):
        self._pin = machine.Pin(pin, machine.Pin.IN, machine.Pin.PULL_UP)
        self._clock = clock
        self._debounce_ms = debounce_ms
        self._candidate = self._down = self._pin.value() == 0
        self._since_ms = clock.now_ms()

    def poll(self):
        level_down = self._pin.value() == 0
        if level_down != self._candidate:
            self._candidate = level_down
            self._since_ms = self._clock.now_ms()
            return EDGE_NONE
        if (
            self._candidate == self._down
            or self._clock.ms_since(self._since_ms) < self._debounce_ms
        ):
            return EDGE_NONE
        self._down = self._candidate
        return EDGE_PRESSED if self._down else EDGE_RELEASED

    def down(self):
        return self._down


def lsm6dsox_imu(i2c_id=0, scl=None, sda=None, freq_hz=400000, address=0x6A):
    """The LSM6DSOX on machine.I2C(i2c_id) (pins scl/sda where the port needs them), set
    up: raises ImuNotFound naming the address when it does not answer."""
    if scl is not None and sda is not None:
        i2c = machine.I2C(i2c_id, scl=machine.Pin(scl), sda=machine.Pin(sda), freq=freq_hz)
    else:
        i2c = machine.I2C(i2c_id, freq=freq_hz)
    imu = Lsm6dsox(i2c, address)
    imu.begin()
    return imu
